"""The metrics document of ``fte simulate`` (CONTRACT.md), computed from a SimulationResult."""

from __future__ import annotations

import numpy as np

from .result import SimulationResult

__all__ = ["metrics", "fault_windows", "state_rms_error", "fault_rel_rms_error", "ftc_deviation_ratio"]

#: state errors are measured after this time (the observer's start-up transient)
SETTLE_T = 1.0
#: fraction of each fault window left out of the fault error (the estimator's settling)
SETTLE_FRACTION = 0.2


def fault_windows(result: SimulationResult) -> list[list[tuple[float, float]]]:
    """Per fault (in the plant's order): the scenario's (start, stop) windows."""
    return [result.scenario.windows(name) for name in result.names["faults"]]


def _mask(t: np.ndarray, windows, settle: float = 0.0) -> np.ndarray:
    m = np.zeros(t.shape, bool)
    for a, b in windows:
        m |= (t >= a + settle * (b - a)) & (t < b)
    return m


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


def ftc_deviation_ratio(y_free, y_noftc, yc_ftc, t, windows) -> float | None:
    """``||yc_FTC - y_free|| / ||y_noFTC - y_free||`` over the union of all fault windows and outputs."""
    keep = _mask(t, [w for ws in windows for w in ws])
    den = np.linalg.norm(y_noftc[:, keep, :] - y_free[:, keep, :])
    if den == 0.0:
        return None
    return float(np.linalg.norm(yc_ftc[:, keep, :] - y_free[:, keep, :]) / den)


def metrics(result: SimulationResult) -> dict:
    """CONTRACT.md's metrics document: paths, dt, T, seed, state_rms_error, fault_rel_rms_error,
    ftc_deviation_ratio, wall_s. Errors use the tolerant-control run; undefined ratios are ``None``."""
    t = result.t
    wins = fault_windows(result)
    ftc = result.ftc
    return {
        "paths": int(result.paths),
        "dt": float(result.dt),
        "T": float(result.T),
        "seed": int(result.seed),
        "state_rms_error": state_rms_error(ftc.x, ftc.xhat, t),
        "fault_rel_rms_error": fault_rel_rms_error(ftc.f, ftc.fhat, t, wins),
        "ftc_deviation_ratio": ftc_deviation_ratio(result.free.y, result.no_ftc.y, ftc.yc, t, wins),
        "wall_s": float(result.wall_s),
    }
