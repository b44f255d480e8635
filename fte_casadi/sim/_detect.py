"""Fault detection on top of the estimates: thresholds from fault-free Monte Carlo at a false-alarm rate.

The residual of fault j is its estimate ``|fhat_j|``. Its threshold is set from fault-free paths that
are independent of the run's own (the same seed, the paths after the run's): each calibration path
gives the peak ``M_p`` of ``|fhat_j|`` after the start-up allowance, over a duration ``D``. The peaks
are fitted with a Gumbel (extreme-value type I) law by moments, ``beta = s sqrt(6) / pi``,
``mu = mean - 0.5772 beta``; the expected number of exceedances of ``x`` in ``D`` is then
``exp(-(x - mu) / beta)``, so the threshold for ``rate`` alarms per unit time is

    threshold = mu - beta ln(rate D).

The run then counts alarms on its own fault-free paths (the rate achieved on independent paths) and on
its FTC run outside the fault's windows. An alarm is raised when ``|fhat_j|`` reaches the threshold and
cleared when it falls below :data:`._reduce.HYSTERESIS` of it; the detection delay of a window is the
time from its start to the first sample at which ``|fhat_j|`` reaches the threshold in it.
"""

from __future__ import annotations

import math

import numpy as np

from ._reduce import HYSTERESIS

__all__ = ["RULE"]  # public: docs/api.md

_EULER = 0.5772156649015329
#: one false alarm per hour of operation, per time unit of the plant
_PER_HOUR = {"s": 1 / 3600.0, "sec": 1 / 3600.0, "ms": 1 / 3.6e6, "min": 1 / 60.0, "h": 1.0, "hour": 1.0}
RULE = (
    "alarm while |fhat_j| >= threshold, cleared below {h:g} x threshold; threshold from a Gumbel fit of the peaks "
    "of |fhat_j| on {n} independent fault-free paths at {rate:.4g} false alarms per unit time"
)


def default_rate(time_unit: str | None) -> float:
    """One false alarm per hour of operation, in alarms per unit of the plant's time (``s`` if unknown)."""
    return _PER_HOUR.get((time_unit or "s").strip().lower(), 1 / 3600.0)


def gumbel_threshold(peaks: np.ndarray, duration: float, rate: float) -> float:
    """The level exceeded ``rate`` times per unit time, from per-path peaks over ``duration`` (a Gumbel fit)."""
    peaks = np.asarray(peaks, dtype=float)
    peaks = peaks[np.isfinite(peaks)]
    if len(peaks) < 2 or duration <= 0:
        return math.inf
    s = float(np.std(peaks, ddof=1))
    beta = s * math.sqrt(6.0) / math.pi
    mu = float(np.mean(peaks)) - _EULER * beta
    thr = mu - beta * math.log(rate * duration)
    top = float(np.max(peaks))
    if beta == 0.0:  # the same peak on every path (no noise): just above it
        thr = top * (1.0 + 1e-6) + 1e-300
    return max(thr, 0.0)


def calibrate(mon: np.ndarray, mon_names: list[str], fault_names, duration: float, rate: float):
    """Thresholds (per fault) and the ``detection`` entries of the metrics document (the achieved rates are
    filled in by :func:`._reduce.finalize`) from the calibration paths' monitor states ``mon``."""
    col = {nm: mon[:, k] for k, nm in enumerate(mon_names)}
    thr, entries = [], []
    for j, name in enumerate(fault_names):
        peaks = col[f"pkc{j}"]
        th = gumbel_threshold(peaks, duration, rate)
        thr.append(th)
        entries.append({
            "fault": name,
            "threshold": th if math.isfinite(th) else None,
            "false_alarm_rate": None,
            "false_alarm_rate_asked": rate,
            "false_alarm_rate_ftc_run": None,
            "calibration_paths": int(mon.shape[0]),
            "calibration_peak_max": float(np.max(peaks)) if len(peaks) else None,
            "rule": RULE.format(h=HYSTERESIS, n=int(mon.shape[0]), rate=rate),
        })  # fmt: skip
    return np.array(thr, dtype=float), entries
