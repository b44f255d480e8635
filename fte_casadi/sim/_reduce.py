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

__all__ = []  # public: docs/api.md

#: fraction of each fault window left out of ``fault_rel_rms_error_settled`` (only there)
SETTLE_FRACTION = 0.2
#: the settling time: the error stays within this fraction of the fault's size
SETTLE_TOL = 0.1
#: an alarm raised at ``|fhat_j| >= threshold`` is cleared when ``|fhat_j|`` falls below this fraction of it
HYSTERESIS = 0.5
#: the start-up allowance and the allowance after a window: this many of the observer's slowest time constant
TAU_MULTIPLE = 3.0
#: ... but at most this share of the shortest fault window (and of the horizon)
WINDOW_SHARE = 0.25


def _mask(t: np.ndarray, windows, settle: float = 0.0) -> np.ndarray:
    m = np.zeros(t.shape, bool)
    for a, b in windows:
        m |= (t >= a + settle * (b - a)) & (t < b)
    return m


@dataclass(frozen=True)
class Allowances:
    """The start-up allowance ``transient`` and the allowance after a window's end ``settle_after``
    (both in the plant's time unit), derived from the observer's slowest time constant ``tau``."""

    transient: float
    settle_after: float
    tau: float
    capped: bool
    why: str


def allowances(design, scenario) -> Allowances:
    """``TAU_MULTIPLE`` x the observer's slowest time constant (``1 / |max Re eig R_i|``); the start-up
    allowance at most half the time before the first fault window (and ``WINDOW_SHARE`` of the horizon),
    the allowance after a window at most ``WINDOW_SHARE`` of the shortest window."""
    re = float(design.checks.get("R_max_real_eig", -math.inf) or -math.inf)
    tau = math.inf if not (math.isfinite(re) and re < 0) else 1.0 / -re
    want = TAU_MULTIPLE * tau
    first = min((float(fp.start) for fp in scenario.faults), default=float(scenario.T))
    cap_t = min(0.5 * first, WINDOW_SHARE * float(scenario.T)) if first > 0 else 0.0
    lengths = [float(fp.stop) - float(fp.start) for fp in scenario.faults]
    cap_a = WINDOW_SHARE * min(lengths) if lengths else want
    transient, after = min(want, cap_t), min(want, cap_a)
    why = (
        f"{TAU_MULTIPLE:g} x the observer's slowest time constant ({TAU_MULTIPLE:g} x {tau:.4g} = {want:.4g})"
    )
    capped = transient < want or after < want
    if transient < want:
        why += f"; the start-up allowance capped at {transient:.4g} (half the time before the first fault)"
    if after < want:
        why += (
            f"; the allowance after a window capped at {after:.4g} ({WINDOW_SHARE:g} of the shortest window)"
        )
    return Allowances(transient, after, tau, capped, why)


@dataclass(frozen=True)
class Masks:
    """Per-sample masks, rows of ``M`` (nmask, samples), in this order: ``after`` (t >= transient);
    per fault its whole windows; per fault its settled windows (each minus its first 20 %); the union of
    all windows; per window all of it; per window its settled part; per fault ``outside`` (after the
    transient, outside its windows and not within ``settle_after`` of one's end)."""

    M: np.ndarray
    fault_of_window: tuple[int, ...]
    windows: tuple[tuple[str, float, float], ...]
    lf: int
    transient: float
    settle_after: float

    @property
    def nw(self) -> int:
        return len(self.windows)

    def row(self, kind: str, k: int = 0) -> int:
        lf, nw = self.lf, self.nw
        base = {"after": 0, "fault": 1, "fault_settled": 1 + lf, "union": 1 + 2 * lf, "window": 2 + 2 * lf,
                "window_settled": 2 + 2 * lf + nw, "outside": 2 + 2 * lf + 2 * nw}[kind]  # fmt: skip
        return base + k


def outside_mask(t: np.ndarray, wins, transient: float, settle_after: float) -> np.ndarray:
    """After ``transient``, outside ``wins`` and not within ``settle_after`` of a window's end."""
    lag = _mask(t, [(b, b + settle_after) for _, b in wins]) if settle_after > 0 else np.zeros(t.shape, bool)
    return (t >= transient) & ~_mask(t, wins) & ~lag


def masks(t: np.ndarray, scenario, fault_names, allow: Allowances) -> Masks:
    names = list(fault_names)
    wins = [list(scenario.windows(nm)) for nm in names]
    prof = [(fp.fault, float(fp.start), float(fp.stop)) for fp in scenario.faults]
    rows = [t >= allow.transient]
    rows += [_mask(t, wins[j]) for j in range(len(names))]
    rows += [_mask(t, wins[j], SETTLE_FRACTION) for j in range(len(names))]
    rows.append(_mask(t, [w for ws in wins for w in ws]))
    rows += [_mask(t, [(a, b)]) for _, a, b in prof]
    rows += [_mask(t, [(a, b)], SETTLE_FRACTION) for _, a, b in prof]
    rows += [outside_mask(t, wins[j], allow.transient, allow.settle_after) for j in range(len(names))]
    M = np.array(rows, dtype=float).reshape(len(rows), len(t))
    return Masks(M, tuple(names.index(f) for f, _, _ in prof), tuple(prof), len(names), allow.transient,
                 allow.settle_after)  # fmt: skip


@dataclass(frozen=True)
class Monitor:
    """The monitor Function ``(rec, mon, sh) -> (mon_next, incr, pm)`` and its layouts.

    ``sh = [mask; t; threshold (lf)]``; ``mon`` per path: per fault the peak ``|fhat_j|`` outside its
    windows (FTC run), the peak ``|f_j|`` in them (FTC run), the peak ``|fhat_j|`` after the transient in
    the fault-free run, the alarm flags of the fault-free and FTC runs; per window the first time the
    FTC run's ``|fhat_j|`` reached the threshold in it (-1: not yet)."""

    fn: ca.Function
    names: list[str]
    mon_names: list[str]
    pm_names: list[str]

    @property
    def nmon(self) -> int:
        return len(self.mon_names)

    def mon0(self) -> np.ndarray:
        """The monitor state at t = 0 (one path)."""
        return np.array([-1.0 if nm.startswith("det") else 0.0 for nm in self.mon_names])


def monitor(lay, mk: Masks, C: np.ndarray, limits, region: tuple[np.ndarray, np.ndarray] | None) -> Monitor:
    """The summands, monitor updates and per-sample maxima of one sample (see :class:`Monitor`).

    ``rec`` is the engine's record of the three runs (free, no_ftc, ftc), each ``[x, xbarhat, f, u, y, yc]``."""
    n, lf, m = lay.n, lay.lf, lay.m
    C = ca.DM(np.asarray(C, dtype=float))
    rec = ca.SX.sym("rec", lay.nrec)
    nm = mk.M.shape[0]
    sh = ca.SX.sym("sh", nm + 1 + lf)
    msk, t, thr = sh[:nm], sh[nm], sh[nm + 1 :]

    def run(r):
        parts, k = {}, r * lay.run_rec
        for name, size in lay.sizes.items():
            parts[name] = rec[k : k + size]
            k += size
        return parts

    free, noftc, ftc = run(0), run(1), run(2)
    fhat = ftc["xbarhat"][n + lf :]
    fhat_free = free["xbarhat"][n + lf :]
    xhat = ftc["xbarhat"][:n]
    row = mk.row
    after = msk[row("after")]
    dC_ftc = ca.mtimes(C, ftc["x"] - free["x"])
    dC_no = ca.mtimes(C, noftc["x"] - free["x"])
    dyc_ftc = ca.sumsqr(ftc["yc"] - free["y"])
    dy_no = ca.sumsqr(noftc["y"] - free["y"])
    out, names = [], []

    def add(name, e):
        out.append(e)
        names.append(name)

    for j in range(n):
        add(f"sx{j}", after * (ftc["x"][j] - xhat[j]) ** 2)
    mon = ca.SX.sym("mon", 5 * lf + mk.nw + mk.nw * lf)
    mon_next, mon_names = [], []
    pk_out, pk_in, pk_cal = [], [], []
    for j in range(lf):
        e2 = (fhat[j] - ftc["f"][j]) ** 2
        f2 = ftc["f"][j] ** 2
        w_j, ws_j, o_j = msk[row("fault", j)], msk[row("fault_settled", j)], msk[row("outside", j)]
        add(f"ef{j}", w_j * e2)
        add(f"ff{j}", w_j * f2)
        add(f"efs{j}", ws_j * e2)
        add(f"ffs{j}", ws_j * f2)
        add(f"oa{j}", o_j * fhat[j] ** 2)
        # alarms with hysteresis: raised at |fhat| >= thr, cleared below HYSTERESIS thr
        al_free, al_ftc = mon[3 * lf + j], mon[4 * lf + j]
        a_free, a_ftc = ca.fabs(fhat_free[j]), ca.fabs(fhat[j])
        add(f"rf{j}", after * (al_free == 0) * (a_free >= thr[j]))
        add(f"ro{j}", o_j * (al_ftc == 0) * (a_ftc >= thr[j]))
        pk_out.append(ca.fmax(mon[j], o_j * a_ftc))
        pk_in.append(ca.fmax(mon[lf + j], w_j * ca.fabs(ftc["f"][j])))
        pk_cal.append(ca.fmax(mon[2 * lf + j], after * a_free))
    mon_next += pk_out + pk_in + pk_cal
    mon_names += (
        [f"pko{j}" for j in range(lf)] + [f"pkf{j}" for j in range(lf)] + [f"pkc{j}" for j in range(lf)]
    )
    al_next_free, al_next_ftc = [], []
    for j in range(lf):
        for lst, al, a in ((al_next_free, mon[3 * lf + j], ca.fabs(fhat_free[j])),
                           (al_next_ftc, mon[4 * lf + j], ca.fabs(fhat[j]))):  # fmt: skip
            lst.append(ca.if_else(al != 0, a >= HYSTERESIS * thr[j], a >= thr[j]))
    mon_next += al_next_free + al_next_ftc
    mon_names += [f"alf{j}" for j in range(lf)] + [f"alc{j}" for j in range(lf)]
    add("a", msk[row("union")] * ca.sumsqr(dC_ftc))
    add("b", msk[row("union")] * ca.sumsqr(dC_no))
    add("ac", msk[row("union")] * dyc_ftc)
    add("bc", msk[row("union")] * dy_no)
    p = C.size1()
    for w in range(mk.nw):
        j = mk.fault_of_window[w]
        m_w, m_ws = msk[row("window", w)], msk[row("window_settled", w)]
        e2 = (fhat[j] - ftc["f"][j]) ** 2
        f2 = ftc["f"][j] ** 2
        add(f"ew{w}", m_w * e2)
        add(f"fw{w}", m_w * f2)
        add(f"ews{w}", m_ws * e2)
        add(f"fws{w}", m_ws * f2)
        for k in range(p):
            add(f"at{w}_{k}", m_w * dC_ftc[k] ** 2)
            add(f"bt{w}_{k}", m_w * dC_no[k] ** 2)
        add(f"acw{w}", m_w * dyc_ftc)
        add(f"bcw{w}", m_w * dy_no)
        det = mon[5 * lf + w]
        mon_next.append(ca.if_else((det < 0) * m_w * (ca.fabs(fhat[j]) >= thr[j]), t, det))
        mon_names.append(f"det{w}")
    for w in range(mk.nw):  # cross-talk: the peak of every fault's estimate in each window
        m_w = msk[row("window", w)]
        for j in range(lf):
            k = 5 * lf + mk.nw + w * lf + j
            mon_next.append(ca.fmax(mon[k], m_w * ca.fabs(fhat[j])))
            mon_names.append(f"xt{w}_{j}")
    lim = None if limits is None else np.asarray(limits, dtype=float)
    for i in range(m):
        at = ca.SX(0.0)
        if lim is not None:
            u = ftc["u"][i]
            if np.isfinite(lim[i, 0]):
                at = at + (u <= float(lim[i, 0]))
            if np.isfinite(lim[i, 1]):
                at = at + (u >= float(lim[i, 1]))
        add(f"sat{i}", at)
        for w in range(mk.nw):
            add(f"satw{w}_{i}", msk[row("window", w)] * at)
    outside = ca.SX(0.0)
    if region is not None:
        lo, hi = (np.asarray(v, dtype=float) for v in region)
        for r in (free, noftc, ftc):
            for j in range(n):
                if np.isfinite(lo[j]):
                    outside = outside + (r["x"][j] < float(lo[j]))
                if np.isfinite(hi[j]):
                    outside = outside + (r["x"][j] > float(hi[j]))
    add("outreg", outside > 0)
    pm, pm_names = [], []
    for j in range(lf):
        pm += [ca.fabs(fhat[j] - ftc["f"][j]), ca.fabs(ftc["f"][j])]
        pm_names += [f"pme{j}", f"pmf{j}"]
    fn = ca.Function(
        "fte_monitor",
        [rec, mon, sh],
        [
            ca.vertcat(*mon_next) if mon_next else ca.SX(0, 1),
            ca.vertcat(*out),
            ca.vertcat(*pm) if pm else ca.SX(0, 1),
        ],
        ["rec", "mon", "sh"],
        ["mon_next", "incr", "pm"],
    )
    return Monitor(fn, names, mon_names, pm_names)


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


def release_mask(t: np.ndarray, mk: Masks, w: int) -> np.ndarray:
    """The samples after window ``w``'s end up to the start of the next fault window of any fault (or the
    horizon): where the estimate falls back to zero undisturbed."""
    _, _, b = mk.windows[w]
    later = [s for _, s, _ in mk.windows if s >= b]
    end = min(later) if later else math.inf
    return (t >= b) & (t < end)


def finalize(acc: np.ndarray, mon: np.ndarray, pm: np.ndarray, t: np.ndarray, mo: Monitor, mk: Masks,
             meta: dict) -> dict:  # fmt: skip
    """The metrics document from per-path sums ``acc`` (paths, len(names)), per-path monitor states ``mon``
    (paths, nmon) and per-sample maxima over the paths ``pm`` (samples, npm), at sample times ``t``.

    ``meta``: ``paths, dt, T, seed, wall_s``, ``m`` (inputs), ``thresholds`` (per fault; inf: none),
    ``detection`` (the document's ``detection`` entries, thresholds and the asked rate, to complete)."""
    col = {nm: acc[:, k] for k, nm in enumerate(mo.names)}
    mcol = {nm: mon[:, k] for k, nm in enumerate(mo.mon_names)}
    pcol = {nm: pm[:, k] for k, nm in enumerate(mo.pm_names)}
    P = acc.shape[0]
    dt = float(meta["dt"])
    nsamp = mk.M.shape[1]
    n_after = float(np.sum(mk.M[mk.row("after")]))
    n = sum(1 for nm in mo.names if nm.startswith("sx"))
    lf = mk.lf
    srms = [
        math.fsum(math.sqrt(v / n_after) for v in col[f"sx{j}"]) / P if n_after else None for j in range(n)
    ]
    n_in = [float(np.sum(mk.M[mk.row("fault", j)])) for j in range(lf)]
    n_out = [float(np.sum(mk.M[mk.row("outside", j)])) for j in range(lf)]
    fa_rms, fa_peak = [], []
    for j in range(lf):
        ff = _fsum(col[f"ff{j}"])
        fa_rms.append(
            _ratio(_fsum(col[f"oa{j}"]) / n_out[j], ff / n_in[j]) if n_out[j] and n_in[j] and ff else None
        )
        size = float(np.max(mcol[f"pkf{j}"]))
        fa_peak.append(float(np.max(mcol[f"pko{j}"])) / size if n_out[j] and size > 0 else None)
    windows = []
    for w, (name, a, b) in enumerate(mk.windows):
        j = mk.fault_of_window[w]
        keep = mk.M[mk.row("window", w)] > 0
        nw = float(np.sum(keep))
        err = pcol[f"pme{j}"][keep] / P
        size = float(np.max(pcol[f"pmf{j}"][keep])) / P if nw else 0.0
        settle = settling_time(err, size, t[keep], a)
        tail = release_mask(t, mk, w)
        release = settling_time(pcol[f"pme{j}"][tail] / P, size, t[tail], b) if tail.any() else None
        p_out = sum(1 for nm in mo.names if nm.startswith(f"at{w}_"))
        det = mcol[f"det{w}"]
        hit = det >= 0
        thr = float(meta["thresholds"][j])
        why = []
        rel = _ratio(_fsum(col[f"ew{w}"]), _fsum(col[f"fw{w}"]))
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
            why.append("no release time: the window ends at the horizon or at the next fault window" if not tail.any()
                       else f"the mean estimate does not fall back within {SETTLE_TOL:g} of the fault's size before the "
                       "next fault window or the horizon")  # fmt: skip
        true_ratio = _ratio(sum(_fsum(col[f"at{w}_{k}"]) for k in range(p_out)),
                            sum(_fsum(col[f"bt{w}_{k}"]) for k in range(p_out))) if rel is not None else None  # fmt: skip
        if rel is not None and true_ratio is None:
            why.append("the fault leaves the true outputs unchanged without tolerant control: no FTC ratio")
        windows.append({
            "fault": name, "start": a, "stop": b,
            "fault_rel_rms_error": rel,
            "fault_rel_rms_error_settled": _ratio(_fsum(col[f"ews{w}"]), _fsum(col[f"fws{w}"])),
            "settling_time": settle,
            "release_time": release,
            "fault_peak": float(np.max(mcol[f"pkf{j}"])) if nw else None,
            "ftc_true_ratio": true_ratio,
            "ftc_true_ratio_per_output": [
                _ratio(_fsum(col[f"at{w}_{k}"]), _fsum(col[f"bt{w}_{k}"])) if rel is not None else None
                for k in range(p_out)
            ],
            "ftc_true_rms_per_output": {
                run: [math.sqrt(_fsum(col[f"{c}{w}_{k}"]) / (P * nw)) if nw else None for k in range(p_out)]
                for run, c in (("ftc", "at"), ("no_ftc", "bt"))
            },
            "ftc_compensated_ratio": _ratio(_fsum(col[f"acw{w}"]), _fsum(col[f"bcw{w}"])) if rel is not None else None,
            "crosstalk_peak": [
                None if q == j or not float(np.max(mcol[f"pkf{q}"])) else
                float(np.max(mcol[f"xt{w}_{q}"])) / float(np.max(mcol[f"pkf{q}"]))
                for q in range(lf)
            ],
            "detection_delay": (math.fsum(float(v) - a for v in det[hit]) / int(hit.sum())) if hit.any() else None,
            "detection_delay_max": float(np.max(det[hit]) - a) if hit.any() else None,
            "missed_detections": int(P - hit.sum()) if math.isfinite(thr) else None,
            "input_saturation": [(_fsum(col[f"satw{w}_{i}"]) / (P * nw)) if nw else 0.0 for i in range(int(meta["m"]))],
            "why": "; ".join(why) or None,
        })  # fmt: skip
    detection = []
    t_after = n_after * dt
    for j, entry in enumerate(meta.get("detection") or []):
        entry = dict(entry)
        if math.isfinite(float(meta["thresholds"][j])):
            entry["false_alarm_rate"] = _fsum(col[f"rf{j}"]) / (P * t_after) if t_after else None
            entry["false_alarm_rate_ftc_run"] = (
                _fsum(col[f"ro{j}"]) / (P * n_out[j] * dt) if n_out[j] else None
            )
        detection.append(entry)
    has_window = any(w["fault_rel_rms_error"] is not None for w in windows)
    return {
        "paths": int(meta["paths"]),
        "dt": dt,
        "T": float(meta["T"]),
        "seed": int(meta["seed"]),
        "observer_time_constant": meta.get("tau"),
        "transient": float(mk.transient),
        "settle_after": float(mk.settle_after),
        "state_rms_error": srms,
        "fault_rel_rms_error": [_ratio(_fsum(col[f"ef{j}"]), _fsum(col[f"ff{j}"])) for j in range(lf)],
        "fault_rel_rms_error_settled": [
            _ratio(_fsum(col[f"efs{j}"]), _fsum(col[f"ffs{j}"])) for j in range(lf)
        ],
        "false_alarm_peak": fa_peak,
        "false_alarm_rel_rms": fa_rms,
        "ftc_true_ratio": _ratio(_fsum(col["a"]), _fsum(col["b"])) if has_window else None,
        "ftc_compensated_ratio": _ratio(_fsum(col["ac"]), _fsum(col["bc"])) if has_window else None,
        "detection": detection,
        "windows": windows,
        "outside_region": _fsum(col["outreg"]) / (P * nsamp),
        "input_saturation": [_fsum(col[f"sat{i}"]) / (P * nsamp) for i in range(int(meta["m"]))],
        "wall_s": float(meta.get("wall_s", 0.0)),
    }
