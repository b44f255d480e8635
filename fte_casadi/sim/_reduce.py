"""The metrics document reduced as the Monte Carlo runs: per-path sums and maxima, combined exactly.

Every metric of the metrics document (docs/interface.md gives each formula) is a function of

- sums over samples, per path, of squared errors under masks that depend on time only (the fault
  windows, the start-up allowance): the ``incr`` output of :func:`monitor`, accumulated in time order;
- per-path running maxima, alarm flags and first-detection times: a small *monitor state* carried
  beside the closed loop's state (``mon``), read back at the end of the horizon;
- per-sample sums over the paths (the fault-estimation error and the fault at each sample, for the
  settling time of the mean error over the paths): the ``pm`` output.

:func:`monitor` writes all three as one CasADi Function of one sample's record, so that the engine
evaluates it in the same compiled loop as the closed loop. :func:`finalize` combines the per-path sums
with ``math.fsum`` (exactly rounded) and the maxima with ``max`` (exact), so a run gives the same
metrics whatever its chunks, threads or workers (the per-sample sums over the paths, added chunk by
chunk, may differ in their last bit with the chunking; they decide only the settling time, a sample
time that moves only on an exact tie with its 10 % band). :func:`fte_casadi.sim._metrics.metrics_from_arrays`
computes the same document from recorded arrays (the reference, equal at ``record_every = 1``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ._intervals import REPLICATES
from ._masks import TAU_MULTIPLE, Masks, after_span, release_mask

__all__ = []  # public: docs/api.md

#: the settling time: the error stays within this fraction of the fault's size
SETTLE_TOL = 0.1
#: an alarm raised at ``|fhat_j| >= threshold`` is cleared when ``|fhat_j|`` falls below this fraction of it
HYSTERESIS = 0.5


@dataclass(frozen=True)
class Monitor:
    """The monitor Function ``(rec, mon, sh) -> (mon_next, incr, pm)`` and its layouts.

    ``sh = [mask; t; threshold (lf)]`` (the thresholds at this sample: a start-up block's own, or the steady
    one); ``mon`` per path (:attr:`mon_names`): per fault the peak ``|fhat_j|`` outside its windows (FTC
    run), with the time and the signed value where it was reached, the same over the two allowances (the
    start-up, and after a window's end), the peak ``|f_j|`` in its windows, the alarm states of the
    fault-free and FTC runs (off until ``transient``); per window the first time the FTC run's alarm rose in
    it (-1: not yet), whether the alarm was already on at its onset (a standing alarm), and the other faults'
    cross-talk peaks; the first time the FTC run's measurement left the range the generated C accepts (-1:
    never); per state its smallest and largest value over the three runs."""

    fn: ca.Function
    names: list[str]
    mon_names: list[str]
    pm_names: list[str]

    @property
    def nmon(self) -> int:
        return len(self.mon_names)

    def mon0(self) -> np.ndarray:
        """The monitor state at t = 0 (one path)."""
        start = {"det": -1.0, "cyt": -1.0, "xlo": _UNSEEN, "xhi": -_UNSEEN}
        return np.array([start.get(nm[:3], 0.0) for nm in self.mon_names])


class _Terms:
    """The monitor's outputs as they are written: the summands (``out``, named ``names``), and the monitor state's
    next values ``nxt`` from its symbols ``slot``."""

    def __init__(self, mon_names: list[str]):
        self.out: list = []
        self.names: list[str] = []
        self.mon = ca.SX.sym("mon", len(mon_names))
        self.slot = {nm_: self.mon[k] for k, nm_ in enumerate(mon_names)}
        self.nxt: dict = {}

    def add(self, name: str, e) -> None:
        self.out.append(e)
        self.names.append(name)

    def peak(self, tag: str, j: int, mask_row, fhat, t) -> None:
        """The running peak of |fhat_j| (FTC run) under a mask, with its time and signed value."""
        slot, nxt = self.slot, self.nxt
        a = mask_row * ca.fabs(fhat[j])
        new = a > slot[f"pk{tag}{j}"]
        nxt[f"pk{tag}{j}"] = ca.fmax(slot[f"pk{tag}{j}"], a)
        nxt[f"tp{tag}{j}"] = ca.if_else(new, t, slot[f"tp{tag}{j}"])
        nxt[f"sp{tag}{j}"] = ca.if_else(new, fhat[j], slot[f"sp{tag}{j}"])


def _monitor_names(lf: int, nw: int, n: int = 0) -> list[str]:
    """The monitor state's entries (see :class:`Monitor`)."""
    return (
        [f"{k}{j}" for k in ("pko", "tpo", "spo", "pks", "tps", "sps", "pkl", "tpl", "spl", "pkf", "alf", "alc")
         for j in range(lf)]
        + [f"{k}{w}" for k in ("det", "stw", "pkw") for w in range(nw)]
        + [f"xt{w}_{j}" for w in range(nw) for j in range(lf)]
        + ["cyt"]
        + [f"{k}{i}" for k in ("xlo", "xhi") for i in range(n)]
    )  # fmt: skip


#: the start of a running minimum (``xlo``) or maximum (``xhi``) of a state (any value seen replaces it)
_UNSEEN = 1e300


def monitor(lay, mk: Masks, C: np.ndarray, limits, region: tuple[np.ndarray, np.ndarray] | None,
            y_range: tuple[np.ndarray, np.ndarray] | None = None) -> Monitor:  # fmt: skip
    """The summands, monitor updates and per-sample maxima of one sample (see :class:`Monitor`).

    ``rec`` is the engine's record of the three runs (free, no_ftc, ftc), each ``[x, xbarhat, f, u, y, yc, ucomp]``;
    ``y_range`` the measurements the generated C accepts (:mod:`._c_range`), per output ``(lo, hi)``."""
    n, lf = lay.n, lay.lf
    C = ca.DM(np.asarray(C, dtype=float))
    rec = ca.SX.sym("rec", lay.nrec)
    nm = mk.M.shape[0]
    sh = ca.SX.sym("sh", nm + 1 + lf)
    msk, t, thr = sh[:nm], sh[nm], sh[nm + 1 :]
    free, noftc, ftc = (_run_parts(lay, rec, r) for r in range(3))
    fhat = ftc["xbarhat"][n + lf :]
    row = mk.row
    after = msk[row("after")]
    dC = (ca.mtimes(C, ftc["x"] - free["x"]), ca.mtimes(C, noftc["x"] - free["x"]))
    dy = (ca.sumsqr(ftc["yc"] - free["y"]), ca.sumsqr(noftc["y"] - free["y"]))
    mon_names = _monitor_names(lf, mk.nw, n)
    s = _Terms(mon_names)
    xhat = ftc["xbarhat"][:n]
    for j in range(n):
        s.add(f"sx{j}", after * (ftc["x"][j] - xhat[j]) ** 2)
    for j in range(lf):
        _fault_terms(s, j, mk, msk, t, thr, fhat, free["xbarhat"][n + lf :], ftc["f"])
    s.add("a", msk[row("union")] * ca.sumsqr(dC[0]))
    s.add("b", msk[row("union")] * ca.sumsqr(dC[1]))
    s.add("ac", msk[row("union")] * dy[0])
    s.add("bc", msk[row("union")] * dy[1])
    for w in range(mk.nw):
        _window_terms(s, w, mk, msk, t, thr, fhat, ftc["f"], dC, dy, C.size1())
    for w in range(mk.nw):  # the compensation applied in each window; both runs' deviation at its onset
        for i in range(lay.m):
            s.add(f"cmp{w}_{i}", msk[row("window", w)] * ftc["ucomp"][i] ** 2)
        s.add(f"ona{w}", msk[row("onset", w)] * ca.sumsqr(dC[0]))
        s.add(f"onb{w}", msk[row("onset", w)] * ca.sumsqr(dC[1]))
    for w in range(mk.nw):  # the span after each window (no fault in the plant): tolerant control's own tail
        m_a = msk[row("after_window", w)]
        for k in range(C.size1()):
            s.add(f"aa{w}_{k}", m_a * dC[0][k] ** 2)
            s.add(f"ba{w}_{k}", m_a * dC[1][k] ** 2)
        for i in range(lay.m):
            s.add(f"cma{w}_{i}", m_a * ftc["ucomp"][i] ** 2)
    for w in range(mk.nw):  # cross-talk: the peak of every fault's estimate in each window
        m_w = msk[row("window", w)]
        for j in range(lf):
            s.nxt[f"xt{w}_{j}"] = ca.fmax(s.slot[f"xt{w}_{j}"], m_w * ca.fabs(fhat[j]))
    _c_range_terms(s, ftc["y"], y_range, lay.p, t)
    for i in range(n):  # where the plant ran: each state's extremes over the three runs
        xs = [r["x"][i] for r in (free, noftc, ftc)]
        s.nxt[f"xlo{i}"] = ca.fmin(s.slot[f"xlo{i}"], ca.fmin(xs[0], ca.fmin(xs[1], xs[2])))
        s.nxt[f"xhi{i}"] = ca.fmax(s.slot[f"xhi{i}"], ca.fmax(xs[0], ca.fmax(xs[1], xs[2])))
    mon_next = [s.nxt[k] for k in mon_names]
    _saturation_terms(s, ftc["u"], limits, lay.m, mk, msk)
    s.add("outreg", _outside_region(region, (free, noftc, ftc), n) > 0)
    pm, pm_names = [], []
    for j in range(lf):
        pm += [ca.fabs(fhat[j] - ftc["f"][j]), ca.fabs(ftc["f"][j])]
        pm_names += [f"pme{j}", f"pmf{j}"]
    fn = ca.Function(
        "fte_monitor",
        [rec, s.mon, sh],
        [
            ca.vertcat(*mon_next) if mon_next else ca.SX(0, 1),
            ca.vertcat(*s.out),
            ca.vertcat(*pm) if pm else ca.SX(0, 1),
        ],
        ["rec", "mon", "sh"],
        ["mon_next", "incr", "pm"],
    )
    return Monitor(fn, s.names, mon_names, pm_names)


def _run_parts(lay, rec, r: int) -> dict:
    """Run ``r``'s signals in one sample's record, by name."""
    parts, k = {}, r * lay.run_rec
    for name, size in lay.sizes.items():
        parts[name] = rec[k : k + size]
        k += size
    return parts


def _fault_terms(s: _Terms, j: int, mk: Masks, msk, t, thr, fhat, fhat_free, f) -> None:
    """Fault j's summands (errors in and outside its windows, the alarms raised) and monitor updates (its peaks
    outside its windows, its size in them, the alarms with hysteresis)."""
    row, slot, nxt = mk.row, s.slot, s.nxt
    after = msk[row("after")]
    e2 = (fhat[j] - f[j]) ** 2
    f2 = f[j] ** 2
    w_j, ws_j, o_j = msk[row("fault", j)], msk[row("fault_settled", j)], msk[row("outside", j)]
    s.add(f"ef{j}", w_j * e2)
    s.add(f"ff{j}", w_j * f2)
    s.add(f"efs{j}", ws_j * e2)
    s.add(f"ffs{j}", ws_j * f2)
    s.add(f"oa{j}", o_j * fhat[j] ** 2)
    # alarms with hysteresis, off until the transient: raised at |fhat| >= thr, cleared below HYSTERESIS thr
    al_free, al_ftc = slot[f"alf{j}"], slot[f"alc{j}"]
    a_free, a_ftc = ca.fabs(fhat_free[j]), ca.fabs(fhat[j])
    s.add(f"rf{j}", after * (al_free == 0) * (a_free >= thr[j]))
    s.add(f"ro{j}", o_j * (al_ftc == 0) * (a_ftc >= thr[j]))
    s.peak("o", j, o_j, fhat, t)
    s.peak("s", j, msk[row("startup_outside", j)], fhat, t)
    s.peak("l", j, msk[row("lag_outside", j)], fhat, t)
    nxt[f"pkf{j}"] = ca.fmax(slot[f"pkf{j}"], w_j * ca.fabs(f[j]))
    for key, al, a in ((f"alf{j}", al_free, a_free), (f"alc{j}", al_ftc, a_ftc)):
        nxt[key] = after * ca.if_else(al != 0, a >= HYSTERESIS * thr[j], a >= thr[j])


def _window_terms(s: _Terms, w: int, mk: Masks, msk, t, thr, fhat, f, dC: tuple, dy: tuple, p: int) -> None:
    """Window w's summands (its fault's error, the true and compensated outputs of the FTC and no-FTC runs) and
    monitor updates (a standing alarm at its onset, the first detection in it)."""
    row, slot, nxt = mk.row, s.slot, s.nxt
    j = mk.fault_of_window[w]
    m_w, m_ws = msk[row("window", w)], msk[row("window_settled", w)]
    e2 = (fhat[j] - f[j]) ** 2
    f2 = f[j] ** 2
    s.add(f"ew{w}", m_w * e2)
    s.add(f"fw{w}", m_w * f2)
    s.add(f"ews{w}", m_ws * e2)
    s.add(f"fws{w}", m_ws * f2)
    for k in range(p):
        s.add(f"at{w}_{k}", m_w * dC[0][k] ** 2)
        s.add(f"bt{w}_{k}", m_w * dC[1][k] ** 2)
    s.add(f"acw{w}", m_w * dy[0])
    s.add(f"bcw{w}", m_w * dy[1])
    nxt[f"pkw{w}"] = ca.fmax(slot[f"pkw{w}"], m_w * ca.fabs(f[j]))  # the fault's peak in this window
    # a standing alarm: the FTC run's alarm already on at the window's onset (a false alarm, not a detection);
    # a detection: the alarm rises in the window on a path where it was off at the onset
    al = slot[f"alc{j}"]
    standing = ca.if_else(msk[row("onset", w)], al != 0, slot[f"stw{w}"])
    nxt[f"stw{w}"] = standing
    after = msk[row("after")]
    rise = (slot[f"det{w}"] < 0) * m_w * after * (al == 0) * (ca.fabs(fhat[j]) >= thr[j]) * (standing == 0)
    nxt[f"det{w}"] = ca.if_else(rise, t, slot[f"det{w}"])


def _saturation_terms(s: _Terms, u, limits, m: int, mk: Masks, msk) -> None:
    """Per input: at a limit (FTC run), over the horizon and in each window."""
    lim = None if limits is None else np.asarray(limits, dtype=float)
    for i in range(m):
        at = ca.SX(0.0)
        if lim is not None:
            if np.isfinite(lim[i, 0]):
                at = at + (u[i] <= float(lim[i, 0]))
            if np.isfinite(lim[i, 1]):
                at = at + (u[i] >= float(lim[i, 1]))
        s.add(f"sat{i}", at)
        for w in range(mk.nw):
            s.add(f"satw{w}_{i}", msk[mk.row("window", w)] * at)


def _c_range_terms(s: _Terms, y, y_range, p: int, t) -> None:
    """Per output, the FTC run's measurement outside the range the generated C accepts (where its step returns 3
    and stops); any of them; the first time it happened (monitor ``cyt``, -1: never)."""
    any_out = ca.SX(0.0)
    for k in range(p):
        out = ca.SX(0.0)
        if y_range is not None:
            out = (y[k] < float(y_range[0][k])) + (y[k] > float(y_range[1][k]))
        s.add(f"cyo{k}", out)
        any_out = any_out + out
    s.add("cya", any_out > 0)
    s.nxt["cyt"] = ca.if_else((s.slot["cyt"] < 0) * (any_out > 0), t, s.slot["cyt"])


def _outside_region(region, runs: tuple, n: int):
    """How many of the states of the three runs lie outside the plant's region (0: none)."""
    outside = ca.SX(0.0)
    if region is not None:
        lo, hi = (np.asarray(v, dtype=float) for v in region)
        for r in runs:
            for j in range(n):
                if np.isfinite(lo[j]):
                    outside = outside + (r["x"][j] < float(lo[j]))
                if np.isfinite(hi[j]):
                    outside = outside + (r["x"][j] > float(hi[j]))
    return outside


def _where_it_ran(c: _Columns) -> dict:
    """``state_range``: each state's smallest and largest value over the three runs, every path and sample; and the
    plant's ``region`` beside it (an open side null)."""
    n = sum(1 for nm in c.mo.mon_names if nm.startswith("xlo"))
    return {
        "state_range": {"lo": [float(np.min(c.mcol[f"xlo{i}"])) for i in range(n)],
                        "hi": [float(np.max(c.mcol[f"xhi{i}"])) for i in range(n)]},
        "region": region_doc(c.meta.get("region")),
    }  # fmt: skip


def region_doc(region) -> dict | None:
    """The plant's region ``(lo, hi)`` as the metrics document holds it: an open side (inf or NaN) null."""
    if region is None:
        return None
    return {
        side: [float(v) if math.isfinite(float(v)) else None for v in vals]
        for side, vals in zip(("lo", "hi"), region)
    }


def _fsum(col) -> float:
    return math.fsum(float(v) for v in col)


def _ratio(num: float, den: float) -> float | None:
    return None if den == 0.0 else float(math.sqrt(num / den))


def settling_time(err: np.ndarray, size: float, t: np.ndarray, start: float) -> float | None:
    """The time after ``start`` from which ``err`` (the samples of one window, in time order: the mean over
    the paths of ``|fhat_j - f_j|``) stays within ``SETTLE_TOL * size`` (``size``: the window's peak of the
    mean over the paths of ``|f_j|``) to the window's end; None when it is outside at the last sample."""
    if size <= 0 or len(err) == 0:
        return None
    out = err > SETTLE_TOL * size
    if out[-1]:
        return None
    last = np.flatnonzero(out)
    k0 = 0 if len(last) == 0 else int(last[-1]) + 1
    return float(t[k0] - start)


def _peak_at(mcol, tag: str, j: int, size: float) -> dict | None:
    """Where the largest of the paths' peaks ``tag`` of fault j was reached: its time, and the signed
    estimate there relative to the fault's size."""
    pk = mcol[f"pk{tag}{j}"]
    if not len(pk) or not size > 0 or not float(np.max(pk)) > 0:
        return None
    k = int(np.argmax(pk))
    return {"t": float(mcol[f"tp{tag}{j}"][k]), "value": float(mcol[f"sp{tag}{j}"][k]) / size}


@dataclass(frozen=True)
class _Columns:
    """What :func:`finalize` reads: the per-path sums ``col``, monitor states ``mcol`` and per-sample sums ``pcol``
    by name, the number of paths ``P``, the sample times, the masks, the monitor and ``meta``."""

    col: dict
    mcol: dict
    pcol: dict
    P: int
    t: np.ndarray
    mo: Monitor
    mk: Masks
    meta: dict

    def n_rows(self, kind: str, j: int = 0) -> float:
        """The samples of mask row ``kind`` (of fault or window ``j``)."""
        return float(np.sum(self.mk.M[self.mk.row(kind, j)]))


def finalize(acc: np.ndarray, mon: np.ndarray, pm: np.ndarray, t: np.ndarray, mo: Monitor, mk: Masks,
             meta: dict) -> dict:  # fmt: skip
    """The metrics document from per-path sums ``acc`` (paths, len(names)), per-path monitor states ``mon``
    (paths, nmon) and per-sample maxima over the paths ``pm`` (samples, npm), at sample times ``t``.

    ``meta``: ``paths, dt, T, seed, wall_s``, ``m`` (inputs), ``thresholds`` (per fault, the steady ones; inf:
    none), ``detection`` (the document's ``detection`` entries, thresholds and the asked rate, to complete),
    ``tau`` (the observer's slowest time constant, or None), ``sensor_gains`` (``|Df|``, outputs by faults, zero
    for a fault that also enters a state equation: how each output reads a sensor fault; optional), ``region``
    (the plant's ``(lo, hi)``, written beside ``state_range``; optional). The intervals (:mod:`._intervals`) are seeded
    by ``seed`` and depend on the set of paths only."""
    from ._intervals import ratio_intervals

    c = _Columns({nm: acc[:, k] for k, nm in enumerate(mo.names)}, {nm: mon[:, k] for k, nm in enumerate(mo.mon_names)},
                 {nm: pm[:, k] for k, nm in enumerate(mo.pm_names)}, acc.shape[0], t, mo, mk, meta)  # fmt: skip
    col, P, lf = c.col, c.P, mk.lf
    seed = int(meta["seed"])
    dt = float(meta["dt"])
    nsamp = mk.M.shape[1]
    n_after = c.n_rows("after")
    n = sum(1 for nm in mo.names if nm.startswith("sx"))
    srms = [
        math.fsum(math.sqrt(v / n_after) for v in col[f"sx{j}"]) / P if n_after else None for j in range(n)
    ]
    n_out = [c.n_rows("outside", j) for j in range(lf)]
    peaks = _false_alarms(c, n_out)
    windows, pairs, tails = [], [], []
    for w in range(len(mk.windows)):
        entry, more = _window(c, w)
        windows.append(entry)
        pairs += more
        tails += _after_window(c, w, entry)
    has_window = any(w["fault_rel_rms_error"] is not None for w in windows)
    globals_ = [(col[f"ef{j}"], col[f"ff{j}"]) for j in range(lf)]
    globals_ += [(col["a"], col["b"]), (col["ac"], col["bc"])]
    both = pairs + globals_ + tails
    iv = ratio_intervals(seed, both) if P else [None] * len(both)
    k_tails = len(pairs) + len(globals_)
    after_window_intervals(windows, iv[k_tails:])
    g = iv[_window_intervals(windows, iv) : k_tails]
    rel_all = [_ratio(_fsum(col[f"ef{j}"]), _fsum(col[f"ff{j}"])) for j in range(lf)]
    true_all, comp_all = _ratio(_fsum(col["a"]), _fsum(col["b"])), _ratio(_fsum(col["ac"]), _fsum(col["bc"]))
    return {
        "paths": int(meta["paths"]),
        "dt": dt,
        "T": float(meta["T"]),
        "seed": seed,
        "observer_time_constant": meta.get("tau"),
        "transient": float(mk.transient),
        "settle_after": float(mk.settle_after),
        "state_rms_error": srms,
        "fault_rel_rms_error": rel_all,
        "fault_rel_rms_error_interval": [g[j] if rel_all[j] is not None else None for j in range(lf)],
        "fault_rel_rms_error_settled": [
            _ratio(_fsum(col[f"efs{j}"]), _fsum(col[f"ffs{j}"])) for j in range(lf)
        ],
        **peaks,
        "ftc_true_ratio": true_all if has_window else None,
        "ftc_true_ratio_interval": g[lf] if has_window and true_all is not None else None,
        "ftc_compensated_ratio": comp_all if has_window else None,
        "ftc_compensated_ratio_interval": g[lf + 1] if has_window and comp_all is not None else None,
        "intervals": {"confidence": 0.95, "bootstrap_replicates": REPLICATES, "over": "paths"},
        "detection": _detection(c, n_after * dt, n_out),
        "windows": windows,
        "outside_region": _fsum(col["outreg"]) / (P * nsamp),
        **_where_it_ran(c),
        "input_saturation": [_fsum(col[f"sat{i}"]) / (P * nsamp) for i in range(int(meta["m"]))],
        **_c_range(c, nsamp),
        "wall_s": float(meta.get("wall_s", 0.0)),
    }


def _c_range(c: _Columns, nsamp: int) -> dict:
    """The FTC run's measurements outside the range the generated C accepts: the fraction of samples (any
    output, and per output), of paths, and the first time (the document's ``outside_c_range*``)."""
    col, P = c.col, c.P
    p = sum(1 for nm in c.mo.names if nm.startswith("cyo"))
    first = c.mcol["cyt"]
    hit = first >= 0
    rng = c.meta.get("y_range")
    accepted = (
        None if rng is None else {side: [float(v) for v in rng[k]] for k, side in enumerate(("lo", "hi"))}
    )
    return {
        "c_accepted_range": accepted,
        "outside_c_range": _fsum(col["cya"]) / (P * nsamp) if P else 0.0,
        "outside_c_range_per_output": [_fsum(col[f"cyo{k}"]) / (P * nsamp) if P else 0.0 for k in range(p)],
        "outside_c_range_paths": float(hit.sum()) / P if P else 0.0,
        "outside_c_range_first": float(np.min(first[hit])) if hit.any() else None,
    }


def _false_alarms(c: _Columns, n_out: list[float]) -> dict:
    """Per fault: the false-alarm peaks (outside its windows, in the start-up, after a window, raw: the largest),
    where they were reached, and the relative RMS outside its windows (the document's ``false_alarm_*``)."""
    col, mcol, mk, P = c.col, c.mcol, c.mk, c.P
    fa_rms, fa_peak, fa_raw, fa_start, fa_lag, fa_at, fa_raw_at = [], [], [], [], [], [], []
    for j in range(mk.lf):
        ff = _fsum(col[f"ff{j}"])
        n_in = c.n_rows("fault", j)
        fa_rms.append(
            _ratio(_fsum(col[f"oa{j}"]) / n_out[j], ff / n_in) if n_out[j] and n_in and ff else None
        )
        size = float(np.max(mcol[f"pkf{j}"])) if P else 0.0
        parts = {}
        for tag, row_ in (("o", "outside"), ("s", "startup_outside"), ("l", "lag_outside")):
            has = c.n_rows(row_, j) > 0
            parts[tag] = float(np.max(mcol[f"pk{tag}{j}"])) / size if has and size > 0 else None
        fa_peak.append(parts["o"])
        fa_start.append(parts["s"])
        fa_lag.append(parts["l"])
        known = [(v, tag) for tag, v in parts.items() if v is not None]
        fa_raw.append(max(v for v, _ in known) if known else None)
        fa_at.append(_peak_at(mcol, "o", j, size) if parts["o"] is not None else None)
        top = max(known)[1] if known else None
        fa_raw_at.append(_peak_at(mcol, top, j, size) if top is not None else None)
    return {
        "false_alarm_peak": fa_peak,
        "false_alarm_peak_raw": fa_raw,
        "false_alarm_peak_startup": fa_start,
        "false_alarm_peak_after_window": fa_lag,
        "false_alarm_peak_at": fa_at,
        "false_alarm_peak_raw_at": fa_raw_at,
        "false_alarm_rel_rms": fa_rms,
    }


def _window(c: _Columns, w: int) -> tuple[dict, list]:
    """Window ``w``'s entry of the document (its intervals filled later, :func:`_window_intervals`), and the
    per-path numerators and denominators of its ratios, bootstrapped together."""
    from ._intervals import clopper_pearson

    col, mcol, pcol, P, mk, t = c.col, c.mcol, c.pcol, c.P, c.mk, c.t
    name, a, b = mk.windows[w]
    j = mk.fault_of_window[w]
    keep = mk.M[mk.row("window", w)] > 0
    nw = float(np.sum(keep))
    err = pcol[f"pme{j}"][keep] / P
    size = float(np.max(pcol[f"pmf{j}"][keep])) / P if nw else 0.0
    settle = settling_time(err, size, t[keep], a)
    tail = release_mask(t, mk, w)
    release = settling_time(pcol[f"pme{j}"][tail] / P, size, t[tail], b) if tail.any() else None
    p_out = sum(1 for nm in c.mo.names if nm.startswith(f"at{w}_"))
    det = mcol[f"det{w}"]
    standing = mcol[f"stw{w}"] != 0
    hit = (det >= 0) & ~standing
    detect = math.isfinite(float(c.meta["thresholds"][j]))
    tau = c.meta.get("tau")
    allowed = min(TAU_MULTIPLE * tau, b - a) if tau is not None and math.isfinite(tau) else b - a
    within = hit & (det - a <= allowed + 1e-9 * max(abs(b), 1.0))
    rel = _ratio(_fsum(col[f"ew{w}"]), _fsum(col[f"fw{w}"]))
    at_ = [col[f"at{w}_{k}"] for k in range(p_out)]
    bt_ = [col[f"bt{w}_{k}"] for k in range(p_out)]
    true_ratio = _ratio(sum(_fsum(v) for v in at_), sum(_fsum(v) for v in bt_)) if rel is not None else None
    why = _window_why(nw, rel, settle, release, tail.any(), true_ratio, detect and hit.sum() == 0)
    peak = float(np.max(mcol[f"pkw{w}"])) if nw else None
    # the per-path numerators and denominators of the window's ratios, bootstrapped together
    pairs = [(col[f"ew{w}"], col[f"fw{w}"]), (np.sum(at_, axis=0), np.sum(bt_, axis=0))]
    pairs += [(at_[k], bt_[k]) for k in range(p_out)] + [(col[f"acw{w}"], col[f"bcw{w}"])]
    entry = {
        "fault": name, "start": a, "stop": b,
        "fault_rel_rms_error": rel,
        "fault_rel_rms_error_settled": _ratio(_fsum(col[f"ews{w}"]), _fsum(col[f"fws{w}"])),
        "settling_time": settle,
        "release_time": release,
        "fault_peak": peak,
        "sensor_fault_peak_per_output": _as_read(c.meta.get("sensor_gains"), j, peak),
        "ftc_true_ratio": true_ratio,
        "ftc_true_ratio_per_output": [
            _ratio(_fsum(col[f"at{w}_{k}"]), _fsum(col[f"bt{w}_{k}"])) if rel is not None else None
            for k in range(p_out)
        ],
        "ftc_true_rms_per_output": {
            run: [math.sqrt(_fsum(col[f"{cc}{w}_{k}"]) / (P * nw)) if nw else None for k in range(p_out)]
            for run, cc in (("ftc", "at"), ("no_ftc", "bt"))
        },
        "ftc_compensated_ratio": _ratio(_fsum(col[f"acw{w}"]), _fsum(col[f"bcw{w}"])) if rel is not None else None,
        "ftc_compensation_rms": [math.sqrt(_fsum(col[f"cmp{w}_{i}"]) / (P * nw)) if nw else None
                                 for i in range(int(c.meta["m"]))],
        "onset_deviation": {run: math.sqrt(_fsum(col[f"{cc}{w}"]) / P) if nw and P else None
                            for run, cc in (("ftc", "ona"), ("no_ftc", "onb"))},
        "crosstalk_peak": [
            None if q == j or not float(np.max(mcol[f"pkf{q}"])) else
            float(np.max(mcol[f"xt{w}_{q}"])) / float(np.max(mcol[f"pkf{q}"]))
            for q in range(mk.lf)
        ],
        "detection_delay": (math.fsum(float(v) - a for v in det[hit]) / int(hit.sum())) if hit.any() else None,
        "detection_delay_max": float(np.max(det[hit]) - a) if hit.any() else None,
        "missed_detections": int(P - standing.sum() - hit.sum()) if detect else None,
        "standing_alarm_paths": int(standing.sum()) if detect else None,
        "detection_probability": float(hit.sum()) / P if detect and P else None,
        "detection_probability_interval": clopper_pearson(int(hit.sum()), P) if detect else None,
        "detection_delay_allowed": float(allowed),
        "detection_probability_within": float(within.sum()) / P if detect and P else None,
        "input_saturation": [(_fsum(col[f"satw{w}_{i}"]) / (P * nw)) if nw else 0.0
                             for i in range(int(c.meta["m"]))],
        "why": "; ".join(why) or None,
    }  # fmt: skip
    return entry, pairs


def sensor_gains(design) -> list:
    """``|Df|`` of ``design`` (outputs by faults) with the columns of faults that also enter a state equation (``Bf``
    or ``Gf`` of some rule) zeroed: how each output reads a fault that enters the measurement only."""
    g = np.abs(np.asarray(design.Df, float))
    for j in range(g.shape[1]):
        if any(np.any(np.asarray(getattr(lm, k))[:, j]) for lm in design.local_models for k in ("Bf", "Gf")):
            g[:, j] = 0.0
    return g.tolist()


def _as_read(gains, j: int, peak: float | None) -> list[float] | None:
    """Fault ``j``'s peak as each output reads it, ``|Df[k, j]| peak`` (``gains``: ``|Df|``, outputs by faults, zero
    for a fault that also enters a state equation): zeros for a fault that does not enter the measurement only;
    None where the window holds no sample (no peak) or the gains are not known."""
    if gains is None or peak is None:
        return None
    return [float(row[j]) * peak for row in gains]


def _after_window(c: _Columns, w: int, entry: dict) -> list:
    """Set window ``w``'s ``after_window`` figures in ``entry`` (:func:`after_window_entry`) and return the per-path
    numerators and denominators of its ratios, bootstrapped with the others (:func:`after_window_intervals`)."""
    col, P, mk = c.col, c.P, c.mk
    p_out = len(entry["ftc_true_ratio_per_output"])
    na = c.n_rows("after_window", w)
    aa = [col[f"aa{w}_{k}"] for k in range(p_out)]
    ba = [col[f"ba{w}_{k}"] for k in range(p_out)]
    cm = [col[f"cma{w}_{i}"] for i in range(int(c.meta["m"]))]
    span = after_span(mk.windows, w, float(c.meta["T"]))
    # the window and the span together: the window's per-path sums plus the span's
    both = (np.sum([col[f"at{w}_{k}"] for k in range(p_out)] + aa, axis=0),
            np.sum([col[f"bt{w}_{k}"] for k in range(p_out)] + ba, axis=0))  # fmt: skip
    sums = (
        [_fsum(v) for v in aa],
        [_fsum(v) for v in ba],
        [_fsum(v) for v in cm],
        (_fsum(both[0]), _fsum(both[1])),
    )
    entry["after_window"] = after_window_entry(span, na * P, sums, entry["fault_rel_rms_error"] is not None)
    return [(np.sum(aa, axis=0), np.sum(ba, axis=0))] + list(zip(aa, ba)) + [both]


def after_window_entry(span: tuple[float, float], n: float, sums: tuple, defined: bool) -> dict | None:
    """The ``after_window`` figures of a window (docs/interface.md): over ``span`` (:func:`after_span`), from ``n``
    (path, sample) pairs with the sums over them of the FTC and no-FTC runs' squared deviations of each true output
    from the fault-free run and of the squared compensation on each input (None: not recorded, as in a result saved
    before the compensation was; the compensation is then null, as the window's), and the FTC and no-FTC runs' sums
    over the window and the span together; None where the span holds no sample or
    the window's fault is zero throughout (``defined`` False). Its intervals come later (:func:`after_window_intervals`)."""
    if not n or not defined:
        return None
    a, b, cm, both = sums
    return {
        "start": span[0], "stop": span[1],
        "ftc_true_ratio": _ratio(math.fsum(a), math.fsum(b)),
        "ftc_true_ratio_with_window": _ratio(*both),
        "ftc_true_ratio_per_output": [_ratio(x, y) for x, y in zip(a, b)],
        "ftc_true_rms_per_output": {"ftc": [math.sqrt(x / n) for x in a], "no_ftc": [math.sqrt(y / n) for y in b]},
        "ftc_compensation_rms": None if cm is None else [math.sqrt(v / n) for v in cm],
    }  # fmt: skip


def after_window_intervals(windows: list[dict], iv: list) -> None:
    """Fill each window's ``after_window`` intervals from ``iv`` (per window: the whole, each output, then the
    window and the span together)."""
    k = 0
    for w in windows:
        p_out = len(w["ftc_true_ratio_per_output"])
        a = w.get("after_window")
        if a is not None:
            a["ftc_true_ratio_interval"] = iv[k] if a["ftc_true_ratio"] is not None else None
            a["ftc_true_ratio_per_output_interval"] = [
                iv[k + 1 + q] if a["ftc_true_ratio_per_output"][q] is not None else None for q in range(p_out)
            ]
            a["ftc_true_ratio_with_window_interval"] = (
                iv[k + 1 + p_out] if a["ftc_true_ratio_with_window"] is not None else None
            )
        k += 2 + p_out


def _window_why(nw: float, rel, settle, release, has_tail: bool, true_ratio, undetected: bool) -> list[str]:
    """Why a window's figures are undefined (null), in words."""
    why = []
    if nw == 0:
        why.append("the window holds no sample")
    elif rel is None:
        why.append("the fault is zero throughout the window: no relative error and no FTC ratio")
    if rel is not None and settle is None:
        why.append(
            f"the mean fault-estimation error does not settle within {SETTLE_TOL:g} of the fault's size by the "
            "window's end"
        )
    if rel is not None and release is None:
        why.append("no release time: the window ends at the horizon or at the next fault window" if not has_tail
                   else f"the mean estimate does not fall back within {SETTLE_TOL:g} of the fault's size before the "
                   "next fault window or the horizon")  # fmt: skip
    if rel is not None and true_ratio is None:
        why.append("the fault leaves the true outputs unchanged without tolerant control: no FTC ratio")
    if undetected:
        why.append(
            "no detection delay: the alarm rose in the window on no path where it was off at its onset"
        )
    return why


def _window_intervals(windows: list[dict], iv: list) -> int:
    """Fill each window's intervals from ``iv`` (in the order of :func:`_window`'s pairs); return how many
    were the windows'."""
    k = 0
    for w in windows:
        p_out = len(w["ftc_true_ratio_per_output"])
        defined = w["fault_rel_rms_error"] is not None
        w["fault_rel_rms_error_interval"] = iv[k] if defined else None
        w["ftc_true_ratio_interval"] = iv[k + 1] if w["ftc_true_ratio"] is not None else None
        w["ftc_true_ratio_per_output_interval"] = [
            iv[k + 2 + q] if w["ftc_true_ratio_per_output"][q] is not None else None for q in range(p_out)
        ]
        w["ftc_compensated_ratio_interval"] = (
            iv[k + 2 + p_out] if w["ftc_compensated_ratio"] is not None else None
        )
        k += 3 + p_out
    return k


def _detection(c: _Columns, t_after: float, n_out: list[float]) -> list[dict]:
    """The document's ``detection`` entries completed with the false-alarm rates and counts this run measured
    (fault-free run after the transient, FTC run outside the fault's windows) and their intervals."""
    from ._intervals import rate_intervals

    col, P, meta = c.col, c.P, c.meta
    seed, dt = int(meta["seed"]), float(meta["dt"])
    detection = []
    counts, exposures, which = [], [], []
    for j, entry in enumerate(meta.get("detection") or []):
        entry = dict(entry)
        if math.isfinite(float(meta["thresholds"][j])):
            entry["false_alarm_rate"] = _fsum(col[f"rf{j}"]) / (P * t_after) if t_after else None
            entry["false_alarm_count"] = int(round(_fsum(col[f"rf{j}"])))
            entry["false_alarm_rate_ftc_run"] = (
                _fsum(col[f"ro{j}"]) / (P * n_out[j] * dt) if n_out[j] else None
            )
            entry["false_alarm_count_ftc_run"] = int(round(_fsum(col[f"ro{j}"])))
            if t_after:
                counts.append(col[f"rf{j}"])
                exposures.append(t_after)
                which.append((j, "false_alarm_rate_measured_interval"))
            if n_out[j]:
                counts.append(col[f"ro{j}"])
                exposures.append(n_out[j] * dt)
                which.append((j, "false_alarm_rate_ftc_run_interval"))
        detection.append(entry)
    for (j, key), v in zip(which, rate_intervals(seed, counts, exposures) if counts and P else []):
        detection[j][key] = v
    return detection
