"""The metrics document reduced as the Monte Carlo runs: per-path sums, combined exactly.

Every metric of the metrics document (docs/interface.md) is a function of sums over samples of squared errors under masks
that depend on time only (the fault windows, ``t >= 1 s``). :func:`increments` writes those
summands as a CasADi Function of one sample's record and the masks of that sample, so that the
engine evaluates it in the same compiled loop as the closed loop and each path accumulates its own
sums in time order. :func:`finalize` combines the per-path sums with ``math.fsum`` (exactly
rounded: the result does not depend on the order of the paths), so a run gives the same metrics
whatever its chunks, threads or workers.

Samples: every simulation step ``k = 0 .. nsteps`` (``t = k dt``); :func:`fte_casadi.sim.metrics`
computes the same document from recorded arrays (the reference, equal at ``record_every = 1``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

__all__ = ["Masks", "masks", "increments", "finalize", "SETTLE_T", "SETTLE_FRACTION"]

#: state errors are measured after this time (the observer's start-up transient)
SETTLE_T = 1.0
#: fraction of each fault window left out of the fault error (the estimator's settling)
SETTLE_FRACTION = 0.2


def _mask(t: np.ndarray, windows, settle: float = 0.0) -> np.ndarray:
    m = np.zeros(t.shape, bool)
    for a, b in windows:
        m |= (t >= a + settle * (b - a)) & (t < b)
    return m


@dataclass(frozen=True)
class Masks:
    """Per-sample masks, rows of ``M`` (nmask, samples): ``t >= 1``, per fault the settled union of
    its windows, the union of all windows, per window its settled part, per window all of it, per
    fault ``t >= 1`` outside all of its windows (where its estimate should be 0)."""

    M: np.ndarray
    fault_of_window: tuple[int, ...]
    windows: tuple[tuple[str, float, float], ...]
    lf: int

    @property
    def nw(self) -> int:
        return len(self.windows)


def masks(t: np.ndarray, scenario, fault_names) -> Masks:
    names = list(fault_names)
    wins = [[w for w in scenario.windows(nm)] for nm in names]
    prof = [(fp.fault, float(fp.start), float(fp.stop)) for fp in scenario.faults]
    rows = [t >= SETTLE_T]
    rows += [_mask(t, wins[j], SETTLE_FRACTION) for j in range(len(names))]
    rows.append(_mask(t, [w for ws in wins for w in ws]))
    rows += [_mask(t, [(a, b)], SETTLE_FRACTION) for _, a, b in prof]
    rows += [_mask(t, [(a, b)]) for _, a, b in prof]
    rows += [(t >= SETTLE_T) & ~_mask(t, wins[j]) for j in range(len(names))]
    M = np.array(rows, dtype=float).reshape(len(rows), len(t))
    return Masks(M, tuple(names.index(f) for f, _, _ in prof), tuple(prof), len(names))


def increments(lay, mk: Masks, limits) -> tuple[ca.Function, list[str]]:
    """``(rec, mask) -> incr``: the summands of one sample, and their names (the layout of the sums).

    ``rec`` is the engine's record of the three runs (free, no_ftc, ftc), each
    ``[x, xbarhat, f, u, y, yc]``."""
    n, lf, m = lay.n, lay.lf, lay.m
    rec = ca.SX.sym("rec", lay.nrec)
    msk = ca.SX.sym("mask", mk.M.shape[0])

    def run(r):
        o = r * lay.run_rec
        parts, k = {}, o
        for name, size in lay.sizes.items():
            parts[name] = rec[k : k + size]
            k += size
        return parts

    free, noftc, ftc = run(0), run(1), run(2)
    xhat, fhat = ftc["xbarhat"][:n], ftc["xbarhat"][n + lf :]
    m_t1, m_f, m_u = msk[0], msk[1 : 1 + lf], msk[1 + lf]
    m_ws = msk[2 + lf : 2 + lf + mk.nw]
    m_w = msk[2 + lf + mk.nw : 2 + lf + 2 * mk.nw]
    m_out = msk[2 + lf + 2 * mk.nw : 2 + 2 * lf + 2 * mk.nw]
    dy_ftc = ca.sumsqr(ftc["yc"] - free["y"])
    dy_no = ca.sumsqr(noftc["y"] - free["y"])
    out, names = [], []

    def add(name, e):
        out.append(e)
        names.append(name)

    for j in range(n):
        add(f"sx{j}", m_t1 * (ftc["x"][j] - xhat[j]) ** 2)
    for j in range(lf):
        add(f"ef{j}", m_f[j] * (fhat[j] - ftc["f"][j]) ** 2)
        add(f"ff{j}", m_f[j] * ftc["f"][j] ** 2)
        add(f"oa{j}", m_out[j] * fhat[j] ** 2)
    add("a", m_u * dy_ftc)
    add("b", m_u * dy_no)
    for w in range(mk.nw):
        j = mk.fault_of_window[w]
        add(f"ew{w}", m_ws[w] * (fhat[j] - ftc["f"][j]) ** 2)
        add(f"fw{w}", m_ws[w] * ftc["f"][j] ** 2)
        add(f"aw{w}", m_w[w] * dy_ftc)
        add(f"bw{w}", m_w[w] * dy_no)
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
            add(f"satw{w}_{i}", m_w[w] * at)
    return ca.Function("fte_increments", [rec, msk], [ca.vertcat(*out)], ["rec", "mask"], ["incr"]), names


def _fsum(col) -> float:
    return math.fsum(float(v) for v in col)


def _ratio(num: float, den: float) -> float | None:
    return None if den == 0.0 else float(math.sqrt(num / den))


def finalize(acc: np.ndarray, names: list[str], mk: Masks, meta: dict) -> dict:
    """The metrics document from per-path sums ``acc`` (paths, len(names)), in path order.

    ``meta``: ``paths, dt, T, seed, wall_s`` and ``m`` (inputs); the counts of samples under each
    mask are taken from the masks themselves."""
    col = {nm: acc[:, k] for k, nm in enumerate(names)}
    P = acc.shape[0]
    n1 = float(np.sum(mk.M[0]))
    nsamp = mk.M.shape[1]
    n = sum(1 for nm in names if nm.startswith("sx"))
    srms = [math.fsum(math.sqrt(v / n1) for v in col[f"sx{j}"]) / P if n1 else None for j in range(n)]
    fault = [_ratio(_fsum(col[f"ef{j}"]), _fsum(col[f"ff{j}"])) for j in range(mk.lf)]
    ratio = _ratio(_fsum(col["a"]), _fsum(col["b"]))
    n_in = [float(np.sum(mk.M[1 + j])) for j in range(mk.lf)]
    n_out = [float(np.sum(mk.M[2 + mk.lf + 2 * mk.nw + j])) for j in range(mk.lf)]
    false_alarm = [
        _ratio(_fsum(col[f"oa{j}"]) / n_out[j], _fsum(col[f"ff{j}"]) / n_in[j])
        if n_out[j] and n_in[j]
        else None
        for j in range(mk.lf)
    ]
    m = int(meta["m"])
    windows = []
    for w, (name, a, b) in enumerate(mk.windows):
        nw = float(np.sum(mk.M[2 + mk.lf + mk.nw + w]))
        windows.append({
            "fault": name, "start": a, "stop": b,
            "fault_rel_rms_error": _ratio(_fsum(col[f"ew{w}"]), _fsum(col[f"fw{w}"])),
            "ftc_deviation_ratio": _ratio(_fsum(col[f"aw{w}"]), _fsum(col[f"bw{w}"])),
            "input_saturation": [(_fsum(col[f"satw{w}_{i}"]) / (P * nw)) if nw else 0.0 for i in range(m)],
        })  # fmt: skip
    return {
        "paths": int(meta["paths"]),
        "dt": float(meta["dt"]),
        "T": float(meta["T"]),
        "seed": int(meta["seed"]),
        "state_rms_error": srms,
        "fault_rel_rms_error": fault,
        "false_alarm_rel_rms": false_alarm,
        "ftc_deviation_ratio": ratio,
        "windows": windows,
        "input_saturation": [_fsum(col[f"sat{i}"]) / (P * nsamp) for i in range(m)],
        "wall_s": float(meta.get("wall_s", 0.0)),
    }
