"""The metrics document of ``fte simulate`` (docs/interface.md), computed from a SimulationResult's arrays.

:func:`metrics_from_arrays` is the reference: every figure by its plain definition over the recorded
paths and samples, equal to the document the engine streamed (:mod:`._reduce`) when every path and every
sample was recorded (``record_all=True, record_every=1``).
"""

from __future__ import annotations

import math

import numpy as np

from ..verdicts import FALSE_ALARM as FALSE_ALARM
from ..verdicts import SATURATED as SATURATED
from ..verdicts import WORSE_THAN_NONE as WORSE_THAN_NONE
from ._reduce import HYSTERESIS, SETTLE_FRACTION, _mask, allowances, outside_mask, settling_time
from ._result import SimulationResult

__all__ = ["metrics", "metrics_from_arrays", "input_saturation", "alarms"]  # public: docs/api.md


def fault_windows(result: SimulationResult) -> list[list[tuple[float, float]]]:
    """Per fault (in the plant's order): the scenario's (start, stop) windows."""
    return [result.scenario.windows(name) for name in result.names["faults"]]


def _rms_ratio(num: np.ndarray, den: np.ndarray) -> float | None:
    d = float(np.sum(den**2))
    return None if d == 0.0 else float(math.sqrt(float(np.sum(num**2)) / d))


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


def alarms(r: np.ndarray, thr: float) -> tuple[np.ndarray, np.ndarray]:
    """``(raised, on)`` of the residual ``r`` (paths, samples): an alarm raised at ``|r| >= thr``, cleared
    below ``HYSTERESIS thr``; ``raised`` marks the samples where it is raised."""
    a = np.abs(r)
    on = np.zeros(a.shape, bool)
    raised = np.zeros(a.shape, bool)
    prev = np.zeros(a.shape[0], bool)
    for k in range(a.shape[1]):
        raised[:, k] = ~prev & (a[:, k] >= thr)
        prev = np.where(prev, a[:, k] >= HYSTERESIS * thr, a[:, k] >= thr)
        on[:, k] = prev
    return raised, on


def _release(t, sc, fp, err, size) -> float | None:
    later = [q.start for q in sc.faults if q.start >= fp.stop]
    tail = (t >= fp.stop) & (t < (min(later) if later else math.inf))
    return settling_time(err[tail], size, t[tail], fp.stop) if tail.any() else None


def metrics_from_arrays(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) recomputed from the recorded arrays (the reference).

    The detection thresholds are the run's own (``result.metrics["detection"]``); without them, none."""
    t = result.t
    dt = float(result.dt) * int(result.record_every)
    sc = result.scenario
    allow = allowances(result.design, sc)
    wins = fault_windows(result)
    free, no, ftc = result.free, result.no_ftc, result.ftc
    C = np.asarray(result.design.C, dtype=float)
    P = ftc.x.shape[0]
    lf = ftc.f.shape[2]
    after = t >= allow.transient
    det_doc = list((result.metrics or {}).get("detection") or [])
    thr = [
        float(det_doc[j]["threshold"])
        if j < len(det_doc) and det_doc[j].get("threshold") is not None
        else math.inf
        for j in range(lf)
    ]
    e = ftc.fhat - ftc.f
    n_after = int(after.sum())
    srms = [float(v) for v in np.sqrt(np.mean((ftc.x[:, after] - ftc.xhat[:, after]) ** 2, axis=1)).mean(axis=0)] if n_after else [None] * ftc.n  # fmt: skip
    rel, rel_s, fa_rms, fa_peak, detection = [], [], [], [], []
    for j in range(lf):
        w, ws = _mask(t, wins[j]), _mask(t, wins[j], SETTLE_FRACTION)
        out = outside_mask(t, wins[j], allow.transient, allow.settle_after)
        rel.append(_rms_ratio(e[:, w, j], ftc.f[:, w, j]))
        rel_s.append(_rms_ratio(e[:, ws, j], ftc.f[:, ws, j]))
        f_rms = float(np.sqrt(np.mean(ftc.f[:, w, j] ** 2))) if w.any() else 0.0
        fa_rms.append(
            float(np.sqrt(np.mean(ftc.fhat[:, out, j] ** 2))) / f_rms if out.any() and f_rms else None
        )
        f_peak = float(np.max(np.abs(ftc.f[:, w, j]))) if w.any() else 0.0
        fa_peak.append(float(np.max(np.abs(ftc.fhat[:, out, j]))) / f_peak if out.any() and f_peak else None)
        if j < len(det_doc):
            entry = dict(det_doc[j])
            if math.isfinite(thr[j]):
                raised_free, _ = alarms(free.fhat[:, :, j], thr[j])
                raised_ftc, _ = alarms(ftc.fhat[:, :, j], thr[j])
                entry["false_alarm_rate"] = (
                    float(raised_free[:, after].sum()) / (P * n_after * dt) if n_after else None
                )
                entry["false_alarm_rate_ftc_run"] = (float(raised_ftc[:, out].sum()) / (P * int(out.sum()) * dt)
                                                     if out.any() else None)  # fmt: skip
            detection.append(entry)
    union = _mask(t, [w for ws in wins for w in ws])
    dC_ftc = (ftc.x - free.x) @ C.T
    dC_no = (no.x - free.x) @ C.T
    has = any(r is not None for r in rel)
    windows = []
    peaks = [
        float(np.max(np.abs(ftc.f[:, _mask(t, wins[q]), q]))) if _mask(t, wins[q]).any() else 0.0
        for q in range(lf)
    ]
    for fp in sc.faults:
        j = list(result.names["faults"]).index(fp.fault)
        w = _mask(t, [(fp.start, fp.stop)])
        ws = _mask(t, [(fp.start, fp.stop)], SETTLE_FRACTION)
        r = _rms_ratio(e[:, w, j], ftc.f[:, w, j])
        size = float(np.max(np.mean(np.abs(ftc.f[:, w, j]), axis=0))) if w.any() else 0.0
        err = np.mean(np.abs(e[:, w, j]), axis=0) if w.any() else np.zeros(0)
        hit_t = []
        if math.isfinite(thr[j]):
            for q in range(P):
                k = np.flatnonzero(w & (np.abs(ftc.fhat[q, :, j]) >= thr[j]))
                if len(k):
                    hit_t.append(float(t[k[0]]) - fp.start)
        windows.append({
            "fault": fp.fault, "start": float(fp.start), "stop": float(fp.stop),
            "fault_rel_rms_error": r,
            "fault_rel_rms_error_settled": _rms_ratio(e[:, ws, j], ftc.f[:, ws, j]),
            "settling_time": settling_time(err, size, t[w], fp.start),
            "release_time": _release(t, sc, fp, np.mean(np.abs(e[:, :, j]), axis=0), size),
            "ftc_true_ratio": _rms_ratio(dC_ftc[:, w], dC_no[:, w]) if r is not None else None,
            "ftc_true_ratio_per_output": [_rms_ratio(dC_ftc[:, w, k], dC_no[:, w, k]) if r is not None else None
                                          for k in range(C.shape[0])],  # fmt: skip
            "ftc_true_rms_per_output": {
                "ftc": [float(np.sqrt(np.mean(dC_ftc[:, w, k] ** 2))) if w.any() else None for k in range(C.shape[0])],
                "no_ftc": [float(np.sqrt(np.mean(dC_no[:, w, k] ** 2))) if w.any() else None for k in range(C.shape[0])],
            },
            "ftc_compensated_ratio": _rms_ratio(ftc.yc[:, w] - free.y[:, w], no.y[:, w] - free.y[:, w]) if r is not None else None,  # fmt: skip
            "crosstalk_peak": [
                None if q == j or not peaks[q] else float(np.max(np.abs(ftc.fhat[:, w, q]))) / peaks[q]
                for q in range(lf)
            ],
            "detection_delay": math.fsum(hit_t) / len(hit_t) if hit_t else None,
            "missed_detections": P - len(hit_t) if math.isfinite(thr[j]) else None,
            "input_saturation": input_saturation(ftc.u, result.design.input_limits, w),
        })  # fmt: skip
    xs = np.stack([free.x, no.x, ftc.x])
    if result.region is None:
        outside = np.zeros(xs.shape[1:3], bool)
    else:
        lo, hi = (np.asarray(v, dtype=float) for v in result.region)
        outside = np.any((xs < lo) | (xs > hi), axis=(0, 3))
    return {
        "paths": int(P),
        "dt": float(result.dt),
        "T": float(result.T),
        "seed": int(result.seed),
        "observer_time_constant": allow.tau if math.isfinite(allow.tau) else None,
        "transient": float(allow.transient),
        "settle_after": float(allow.settle_after),
        "state_rms_error": srms,
        "fault_rel_rms_error": rel,
        "fault_rel_rms_error_settled": rel_s,
        "false_alarm_peak": fa_peak,
        "false_alarm_rel_rms": fa_rms,
        "ftc_true_ratio": _rms_ratio(dC_ftc[:, union], dC_no[:, union]) if has else None,
        "ftc_compensated_ratio": _rms_ratio(
            ftc.yc[:, union] - free.y[:, union], no.y[:, union] - free.y[:, union]
        )
        if has
        else None,  # fmt: skip
        "detection": detection,
        "windows": windows,
        "outside_region": float(outside.mean()),
        "input_saturation": input_saturation(ftc.u, result.design.input_limits),
        "wall_s": float(result.wall_s),
    }


def metrics(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) of a run: the one the engine streamed over all its paths, or,
    for a result without it (the per-path engine), :func:`metrics_from_arrays`."""
    return dict(result.metrics) if result.metrics is not None else metrics_from_arrays(result)
