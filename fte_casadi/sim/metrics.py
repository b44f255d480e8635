"""The metrics document of ``fte simulate`` (docs/interface.md), computed from a SimulationResult."""

from __future__ import annotations

import numpy as np

from .result import SimulationResult

__all__ = ["metrics", "metrics_from_arrays", "windows", "input_saturation", "fault_windows", "state_rms_error",
           "fault_rel_rms_error", "false_alarm_rel_rms", "ftc_deviation_ratio", "WORSE_THAN_NONE", "FALSE_ALARM",
           "SATURATED"]  # fmt: skip

from ..verdicts import FALSE_ALARM, SATURATED, WORSE_THAN_NONE  # re-exported: the verdicts of this document
from .reduce import SETTLE_FRACTION, SETTLE_T, _mask


def fault_windows(result: SimulationResult) -> list[list[tuple[float, float]]]:
    """Per fault (in the plant's order): the scenario's (start, stop) windows."""
    return [result.scenario.windows(name) for name in result.names["faults"]]


def state_rms_error(x: np.ndarray, xhat: np.ndarray, t: np.ndarray, t_from: float = SETTLE_T) -> list[float]:
    """RMS over ``t >= t_from`` of ``x - xhat`` per state and path, then mean over paths. Arrays (paths, samples, n)."""
    keep = t >= t_from
    e = x[:, keep, :] - xhat[:, keep, :]
    return [float(v) for v in np.sqrt(np.mean(e**2, axis=1)).mean(axis=0)]


def fault_rel_rms_error(f: np.ndarray, fhat: np.ndarray, t: np.ndarray, windows) -> list[float | None]:
    """Per fault j: RMS(fhat - f) / RMS(f) over its windows minus their first 20 %, all paths pooled.

    ``None`` for a fault with no window (or identically zero there): the ratio is undefined.
    """
    out = []
    for j, wins in enumerate(windows):
        keep = _mask(t, wins, SETTLE_FRACTION)
        fj = f[:, keep, j]
        den = np.sqrt(np.mean(fj**2)) if fj.size else 0.0
        if den == 0.0:
            out.append(None)
            continue
        out.append(float(np.sqrt(np.mean((fhat[:, keep, j] - fj) ** 2)) / den))
    return out


def false_alarm_rel_rms(f: np.ndarray, fhat: np.ndarray, t: np.ndarray, windows) -> list[float | None]:
    """Per fault j: RMS(fhat_j) over ``t >= 1 s`` outside all of its windows (where f_j = 0: what the
    estimate shows there is a false alarm, e.g. cross-talk from another fault) divided by RMS(f_j) over
    its windows minus their first 20 % (the denominator of :func:`fault_rel_rms_error`), paths pooled.

    ``None`` when either set of samples is empty or f_j is zero in its windows."""
    out = []
    for j, wins in enumerate(windows):
        inside, outside = _mask(t, wins, SETTLE_FRACTION), (t >= SETTLE_T) & ~_mask(t, wins)
        fj = f[:, inside, j]
        den = np.sqrt(np.mean(fj**2)) if fj.size else 0.0
        if den == 0.0 or not outside.any():
            out.append(None)
            continue
        out.append(float(np.sqrt(np.mean(fhat[:, outside, j] ** 2)) / den))
    return out


def ftc_deviation_ratio(y_free, y_noftc, yc_ftc, t, windows) -> float | None:
    """``||yc_FTC - y_free|| / ||y_noFTC - y_free||`` over the union of all fault windows and outputs."""
    keep = _mask(t, [w for ws in windows for w in ws])
    den = np.linalg.norm(y_noftc[:, keep, :] - y_free[:, keep, :])
    if den == 0.0:
        return None
    return float(np.linalg.norm(yc_ftc[:, keep, :] - y_free[:, keep, :]) / den)


def input_saturation(u: np.ndarray, limits, mask: np.ndarray | None = None) -> list[float]:
    """Per input: the fraction of (path, sample) pairs with ``u`` at a limit (under ``mask`` over samples)."""
    m = u.shape[2]
    if limits is None:
        return [0.0] * m
    lim = np.asarray(limits, dtype=float)
    keep = np.ones(u.shape[1], bool) if mask is None else mask
    if not keep.any():
        return [0.0] * m
    at = (u[:, keep, :] <= lim[:, 0]) | (u[:, keep, :] >= lim[:, 1])
    return [float(v) for v in at.mean(axis=(0, 1))]


def windows(result: SimulationResult) -> list[dict]:
    """One entry per fault profile of the scenario (in its order): the fault's relative RMS error over
    the window minus its first 20 % and the FTC deviation ratio over the window, FTC run, paths pooled;
    and per input the fraction of the window's samples at a limit."""
    t, ftc = result.t, result.ftc
    names = list(result.names["faults"])
    out = []
    for fp in result.scenario.faults:
        j = names.index(fp.fault)
        err = fault_rel_rms_error(
            ftc.f[:, :, j : j + 1], ftc.fhat[:, :, j : j + 1], t, [[(fp.start, fp.stop)]]
        )[0]
        ratio = ftc_deviation_ratio(result.free.y, result.no_ftc.y, ftc.yc, t, [[(fp.start, fp.stop)]])
        m = _mask(t, [(fp.start, fp.stop)])
        out.append({"fault": fp.fault, "start": float(fp.start), "stop": float(fp.stop), "fault_rel_rms_error": err,
                    "ftc_deviation_ratio": ratio,
                    "input_saturation": input_saturation(ftc.u, result.design.input_limits, m)})  # fmt: skip
    return out


def metrics_from_arrays(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) recomputed from the recorded arrays (the reference).

    Over the recorded paths and samples only: equal to the streamed document of the run when every
    path and every sample was recorded (``record_all=True, record_every=1``)."""
    t = result.t
    wins = fault_windows(result)
    ftc = result.ftc
    return {
        "paths": int(ftc.x.shape[0]),
        "dt": float(result.dt),
        "T": float(result.T),
        "seed": int(result.seed),
        "state_rms_error": state_rms_error(ftc.x, ftc.xhat, t),
        "fault_rel_rms_error": fault_rel_rms_error(ftc.f, ftc.fhat, t, wins),
        "false_alarm_rel_rms": false_alarm_rel_rms(ftc.f, ftc.fhat, t, wins),
        "ftc_deviation_ratio": ftc_deviation_ratio(result.free.y, result.no_ftc.y, ftc.yc, t, wins),
        "windows": windows(result),
        "input_saturation": input_saturation(ftc.u, result.design.input_limits),
        "wall_s": float(result.wall_s),
    }


def metrics(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) of a run: the one the engine streamed over all its paths, or,
    for a result without it (the per-path engine), :func:`metrics_from_arrays`."""
    return dict(result.metrics) if result.metrics is not None else metrics_from_arrays(result)
