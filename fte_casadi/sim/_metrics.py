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
from ._intervals import clopper_pearson, rate_intervals, ratio_intervals
from ._reduce import (
    HYSTERESIS,
    SETTLE_FRACTION,
    _mask,
    allowance_masks,
    allowances,
    outside_mask,
    settling_time,
)
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


def alarms(r: np.ndarray, thr, after: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """``(raised, on)`` of the residual ``r`` (paths, samples): an alarm raised at ``|r| >= thr``, cleared
    below ``HYSTERESIS thr``, off wherever ``after`` is False (before the start-up allowance's end); ``thr`` a
    number or one per sample; ``raised`` marks the samples where it is raised, ``on`` its state after each."""
    a = np.abs(r)
    thr = np.broadcast_to(np.asarray(thr, dtype=float), (a.shape[1],))
    after = np.ones(a.shape[1], bool) if after is None else np.asarray(after, bool)
    on = np.zeros(a.shape, bool)
    raised = np.zeros(a.shape, bool)
    prev = np.zeros(a.shape[0], bool)
    for k in range(a.shape[1]):
        raised[:, k] = after[k] & ~prev & (a[:, k] >= thr[k])
        prev = after[k] & np.where(prev, a[:, k] >= HYSTERESIS * thr[k], a[:, k] >= thr[k])
        on[:, k] = prev
    return raised, on


def threshold_at(entry: dict | None, t: np.ndarray) -> np.ndarray:
    """A ``detection`` entry's threshold at the sample times ``t``: a start-up block's own, else the steady
    one (inf without a threshold)."""
    out = np.full(t.shape, np.inf)
    if entry is None or entry.get("threshold") is None:
        return out
    out[:] = float(entry["threshold"])
    for b in entry.get("startup_thresholds") or []:
        out[(t >= b["start"]) & (t < b["stop"])] = float(b["threshold"])
    return out


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
    thr = [threshold_at(det_doc[j] if j < len(det_doc) else None, t) for j in range(lf)]
    detect = [bool(np.isfinite(thr[j]).any()) for j in range(lf)]
    seed = int(result.seed)
    e = ftc.fhat - ftc.f
    n_after = int(after.sum())
    srms = [float(v) for v in np.sqrt(np.mean((ftc.x[:, after] - ftc.xhat[:, after]) ** 2, axis=1)).mean(axis=0)] if n_after else [None] * ftc.n  # fmt: skip
    rel, rel_s, fa_rms, fa_peak, detection = [], [], [], [], []
    fa_start, fa_lag, fa_raw, fa_at, fa_raw_at = [], [], [], [], []
    counts, exposures, which, on_ftc = [], [], [], []
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
        parts = {}
        for tag, m_ in zip("osl", (out, *allowance_masks(t, wins[j], allow.transient, allow.settle_after))):
            if m_.any() and f_peak:
                a_ = np.abs(ftc.fhat[:, m_, j])
                q, k = np.unravel_index(int(np.argmax(a_)), a_.shape)
                parts[tag] = (
                    float(a_[q, k]) / f_peak,
                    {"t": float(t[m_][k]), "value": float(ftc.fhat[q, m_, j][k]) / f_peak},
                )
        fa_peak.append(parts["o"][0] if "o" in parts else None)
        fa_start.append(parts["s"][0] if "s" in parts else None)
        fa_lag.append(parts["l"][0] if "l" in parts else None)
        fa_at.append(parts["o"][1] if "o" in parts else None)
        top = max(parts.values(), key=lambda v: v[0]) if parts else None
        fa_raw.append(top[0] if top else None)
        fa_raw_at.append(top[1] if top else None)
        _, on = alarms(ftc.fhat[:, :, j], thr[j], after) if detect[j] else (None, None)
        on_ftc.append(on)
        if j < len(det_doc):
            entry = dict(det_doc[j])
            if detect[j]:
                raised_free, _ = alarms(free.fhat[:, :, j], thr[j], after)
                raised_ftc, _ = alarms(ftc.fhat[:, :, j], thr[j], after)
                entry["false_alarm_rate"] = (
                    float(raised_free[:, after].sum()) / (P * n_after * dt) if n_after else None
                )
                entry["false_alarm_count"] = int(raised_free[:, after].sum())
                entry["false_alarm_rate_ftc_run"] = (float(raised_ftc[:, out].sum()) / (P * int(out.sum()) * dt)
                                                     if out.any() else None)  # fmt: skip
                entry["false_alarm_count_ftc_run"] = int(raised_ftc[:, out].sum())
                if n_after:
                    counts.append(raised_free[:, after].sum(axis=1)), exposures.append(n_after * dt)
                    which.append((len(detection), "false_alarm_rate_measured_interval"))
                if out.any():
                    counts.append(raised_ftc[:, out].sum(axis=1)), exposures.append(int(out.sum()) * dt)
                    which.append((len(detection), "false_alarm_rate_ftc_run_interval"))
            detection.append(entry)
    for (k, key), v in zip(which, rate_intervals(seed, counts, exposures) if counts else []):
        detection[k][key] = v
    union = _mask(t, [w for ws in wins for w in ws])
    dC_ftc = (ftc.x - free.x) @ C.T
    dC_no = (no.x - free.x) @ C.T
    has = any(r is not None for r in rel)
    windows, pairs = [], []
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
        hit_t, standing = [], 0
        if detect[j]:
            raised, on = alarms(ftc.fhat[:, :, j], thr[j], after)
            k0 = np.flatnonzero(t >= fp.start)
            for q in range(P):
                if len(k0) and k0[0] > 0 and on[q, k0[0] - 1]:
                    standing += 1  # the alarm on at the onset: a standing false alarm, not a detection
                    continue
                k = np.flatnonzero(w & raised[q])
                if len(k):
                    hit_t.append(float(t[k[0]]) - fp.start)
        tau = allow.tau
        allowed = min(3.0 * tau, fp.stop - fp.start) if math.isfinite(tau) else fp.stop - fp.start
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
            "detection_delay_max": max(hit_t) if hit_t else None,
            "missed_detections": P - standing - len(hit_t) if detect[j] else None,
            "standing_alarm_paths": standing if detect[j] else None,
            "detection_probability": len(hit_t) / P if detect[j] else None,
            "detection_probability_interval": clopper_pearson(len(hit_t), P) if detect[j] else None,
            "detection_delay_allowed": float(allowed),
            "detection_probability_within": sum(1 for v in hit_t if v <= allowed + 1e-9 * max(abs(fp.stop), 1.0)) / P
            if detect[j] else None,
            "input_saturation": input_saturation(ftc.u, result.design.input_limits, w),
        })  # fmt: skip
        sq = lambda v: np.sum(v**2, axis=tuple(range(1, v.ndim)))  # noqa: E731 - per path
        pairs += [(sq(e[:, w, j]), sq(ftc.f[:, w, j])), (sq(dC_ftc[:, w]), sq(dC_no[:, w]))]
        pairs += [(sq(dC_ftc[:, w, k]), sq(dC_no[:, w, k])) for k in range(C.shape[0])]
        pairs += [(sq(ftc.yc[:, w] - free.y[:, w]), sq(no.y[:, w] - free.y[:, w]))]
    sq = lambda v: np.sum(v**2, axis=tuple(range(1, v.ndim)))  # noqa: E731
    glob = [(sq(e[:, _mask(t, wins[j]), j]), sq(ftc.f[:, _mask(t, wins[j]), j])) for j in range(lf)]
    glob += [(sq(dC_ftc[:, union]), sq(dC_no[:, union])), (sq(ftc.yc[:, union] - free.y[:, union]),
             sq(no.y[:, union] - free.y[:, union]))]  # fmt: skip
    iv = ratio_intervals(seed, pairs + glob)
    k = 0
    for wd in windows:
        p_out = len(wd["ftc_true_ratio_per_output"])
        wd["fault_rel_rms_error_interval"] = iv[k] if wd["fault_rel_rms_error"] is not None else None
        wd["ftc_true_ratio_interval"] = iv[k + 1] if wd["ftc_true_ratio"] is not None else None
        wd["ftc_true_ratio_per_output_interval"] = [
            iv[k + 2 + q] if wd["ftc_true_ratio_per_output"][q] is not None else None for q in range(p_out)
        ]
        wd["ftc_compensated_ratio_interval"] = (
            iv[k + 2 + p_out] if wd["ftc_compensated_ratio"] is not None else None
        )
        k += 3 + p_out
    g = iv[k:]
    true_all = _rms_ratio(dC_ftc[:, union], dC_no[:, union]) if has else None
    comp_all = (
        _rms_ratio(ftc.yc[:, union] - free.y[:, union], no.y[:, union] - free.y[:, union]) if has else None
    )
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
        "fault_rel_rms_error_interval": [g[j] if rel[j] is not None else None for j in range(lf)],
        "fault_rel_rms_error_settled": rel_s,
        "false_alarm_peak": fa_peak,
        "false_alarm_peak_raw": fa_raw,
        "false_alarm_peak_startup": fa_start,
        "false_alarm_peak_after_window": fa_lag,
        "false_alarm_peak_at": fa_at,
        "false_alarm_peak_raw_at": fa_raw_at,
        "false_alarm_rel_rms": fa_rms,
        "ftc_true_ratio": true_all,
        "ftc_true_ratio_interval": g[lf] if true_all is not None else None,
        "ftc_compensated_ratio": comp_all,
        "ftc_compensated_ratio_interval": g[lf + 1] if comp_all is not None else None,
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
