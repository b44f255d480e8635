"""The metrics document of ``fte simulate`` (docs/interface.md), computed from a SimulationResult's arrays.

:func:`metrics_from_arrays` is the reference: every figure by its plain definition over the recorded
paths and samples, equal to the document the engine streamed (:mod:`._reduce`) when every path and every
sample was recorded (``record_all=True, record_every=1``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..verdicts import FALSE_ALARM as FALSE_ALARM
from ..verdicts import SATURATED as SATURATED
from ..verdicts import WORSE_THAN_NONE as WORSE_THAN_NONE
from ._intervals import clopper_pearson, rate_intervals, ratio_intervals
from ._masks import SETTLE_FRACTION, _mask, after_span, allowance_masks, allowances, onset_mask, outside_mask
from ._reduce import HYSTERESIS, region_doc, sensor_gains, settling_time
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


@dataclass(frozen=True)
class _Run:
    """What :func:`metrics_from_arrays` reads from a result: the recorded runs, the sample times and step, the
    allowances and windows, the detection thresholds at each sample, and the differences of the outputs."""

    result: SimulationResult
    t: np.ndarray
    dt: float
    allow: object
    wins: list
    after: np.ndarray
    thr: list
    detect: list
    det_doc: list
    e: np.ndarray
    dC_ftc: np.ndarray
    dC_no: np.ndarray

    @property
    def P(self) -> int:
        return self.result.ftc.x.shape[0]

    @property
    def n_after(self) -> int:
        return int(self.after.sum())


def _sq(v: np.ndarray) -> np.ndarray:
    """Per path: the sum of squares over the other axes."""
    return np.sum(v**2, axis=tuple(range(1, v.ndim)))


def metrics_from_arrays(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) recomputed from the recorded arrays (the reference).

    The detection thresholds are the run's own (``result.metrics["detection"]``); without them, none."""
    from ._reduce import _window_intervals, after_window_intervals

    t = result.t
    allow = allowances(result.design, result.scenario)
    free, no, ftc = result.free, result.no_ftc, result.ftc
    C = np.asarray(result.design.C, dtype=float)
    lf = ftc.f.shape[2]
    det_doc = list((result.metrics or {}).get("detection") or [])
    thr = [threshold_at(det_doc[j] if j < len(det_doc) else None, t) for j in range(lf)]
    c = _Run(result, t, float(result.dt) * int(result.record_every), allow, fault_windows(result), t >= allow.transient,
             thr, [bool(np.isfinite(thr[j]).any()) for j in range(lf)], det_doc, ftc.fhat - ftc.f,
             (ftc.x - free.x) @ C.T, (no.x - free.x) @ C.T)  # fmt: skip
    after, wins, P = c.after, c.wins, c.P
    srms = [float(v) for v in np.sqrt(np.mean((ftc.x[:, after] - ftc.xhat[:, after]) ** 2, axis=1)).mean(axis=0)] if c.n_after else [None] * ftc.n  # fmt: skip
    faults = _per_fault(c)
    rel = faults["fault_rel_rms_error"]
    union = _mask(t, [w for ws in wins for w in ws])
    windows, pairs, tails = [], [], []
    peaks = [
        float(np.max(np.abs(ftc.f[:, _mask(t, wins[q]), q]))) if _mask(t, wins[q]).any() else 0.0
        for q in range(lf)
    ]
    for fp in result.scenario.faults:
        entry, more = _window_from_arrays(c, fp, peaks)
        windows.append(entry)
        pairs += more
        tails += _after_window_from_arrays(c, len(windows) - 1, entry)
    e, dC_ftc, dC_no = c.e, c.dC_ftc, c.dC_no
    glob = [(_sq(e[:, _mask(t, wins[j]), j]), _sq(ftc.f[:, _mask(t, wins[j]), j])) for j in range(lf)]
    glob += [(_sq(dC_ftc[:, union]), _sq(dC_no[:, union])), (_sq(ftc.yc[:, union] - free.y[:, union]),
             _sq(no.y[:, union] - free.y[:, union]))]  # fmt: skip
    iv = ratio_intervals(int(result.seed), pairs + glob + tails)
    after_window_intervals(windows, iv[len(pairs) + len(glob) :])
    g = iv[_window_intervals(windows, iv) : len(pairs) + len(glob)]
    has = any(r is not None for r in rel)
    true_all = _rms_ratio(dC_ftc[:, union], dC_no[:, union]) if has else None
    comp_all = (
        _rms_ratio(ftc.yc[:, union] - free.y[:, union], no.y[:, union] - free.y[:, union]) if has else None
    )
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
        **{k: v for k, v in faults.items() if k not in ("fault_rel_rms_error", "detection")},
        "ftc_true_ratio": true_all,
        "ftc_true_ratio_interval": g[lf] if true_all is not None else None,
        "ftc_compensated_ratio": comp_all,
        "ftc_compensated_ratio_interval": g[lf + 1] if comp_all is not None else None,
        "detection": faults["detection"],
        "windows": windows,
        "outside_region": float(_outside_region(result).mean()),
        **_where_it_ran(result),
        "input_saturation": input_saturation(ftc.u, result.design.input_limits),
        **_outside_c_range(result),
        "wall_s": float(result.wall_s),
    }


def _per_fault(c: _Run) -> dict:
    """Per fault: the relative errors (whole windows, settled part), the false-alarm peaks (and where they were
    reached) and relative RMS, in the document's order, and the ``detection`` entries completed."""
    t, ftc, allow, e = c.t, c.result.ftc, c.allow, c.e
    rel, rel_s, fa_rms, fa_peak = [], [], [], []
    fa_start, fa_lag, fa_raw, fa_at, fa_raw_at = [], [], [], [], []
    for j in range(ftc.f.shape[2]):
        wins = c.wins[j]
        w, ws = _mask(t, wins), _mask(t, wins, SETTLE_FRACTION)
        out = outside_mask(t, wins, allow.transient, allow.settle_after)
        rel.append(_rms_ratio(e[:, w, j], ftc.f[:, w, j]))
        rel_s.append(_rms_ratio(e[:, ws, j], ftc.f[:, ws, j]))
        f_rms = float(np.sqrt(np.mean(ftc.f[:, w, j] ** 2))) if w.any() else 0.0
        fa_rms.append(
            float(np.sqrt(np.mean(ftc.fhat[:, out, j] ** 2))) / f_rms if out.any() and f_rms else None
        )
        f_peak = float(np.max(np.abs(ftc.f[:, w, j]))) if w.any() else 0.0
        parts = {}
        for tag, m_ in zip("osl", (out, *allowance_masks(t, wins, allow.transient, allow.settle_after))):
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
    return {
        "fault_rel_rms_error": rel,
        "fault_rel_rms_error_settled": rel_s,
        "false_alarm_peak": fa_peak,
        "false_alarm_peak_raw": fa_raw,
        "false_alarm_peak_startup": fa_start,
        "false_alarm_peak_after_window": fa_lag,
        "false_alarm_peak_at": fa_at,
        "false_alarm_peak_raw_at": fa_raw_at,
        "false_alarm_rel_rms": fa_rms,
        "detection": _detection_from_arrays(c),
    }


def _detection_from_arrays(c: _Run) -> list[dict]:
    """The run's ``detection`` entries completed with the false-alarm rates and counts counted on the arrays
    (fault-free run after the transient, FTC run outside the fault's windows) and their intervals."""
    t, after, dt, P, n_after = c.t, c.after, c.dt, c.P, c.n_after
    free, ftc = c.result.free, c.result.ftc
    detection, counts, exposures, which = [], [], [], []
    for j in range(min(ftc.f.shape[2], len(c.det_doc))):
        out = outside_mask(t, c.wins[j], c.allow.transient, c.allow.settle_after)
        entry = dict(c.det_doc[j])
        if c.detect[j]:
            raised_free, _ = alarms(free.fhat[:, :, j], c.thr[j], after)
            raised_ftc, _ = alarms(ftc.fhat[:, :, j], c.thr[j], after)
            entry["false_alarm_rate"] = (
                float(raised_free[:, after].sum()) / (P * n_after * dt) if n_after else None
            )
            entry["false_alarm_count"] = int(raised_free[:, after].sum())
            entry["false_alarm_rate_ftc_run"] = (float(raised_ftc[:, out].sum()) / (P * int(out.sum()) * dt)
                                                 if out.any() else None)  # fmt: skip
            entry["false_alarm_count_ftc_run"] = int(raised_ftc[:, out].sum())
            if n_after:
                counts.append(raised_free[:, after].sum(axis=1))
                exposures.append(n_after * dt)
                which.append((len(detection), "false_alarm_rate_measured_interval"))
            if out.any():
                counts.append(raised_ftc[:, out].sum(axis=1))
                exposures.append(int(out.sum()) * dt)
                which.append((len(detection), "false_alarm_rate_ftc_run_interval"))
        detection.append(entry)
    for (k, key), v in zip(which, rate_intervals(int(c.result.seed), counts, exposures) if counts else []):
        detection[k][key] = v
    return detection


def _detections(c: _Run, fp, j: int, w: np.ndarray) -> tuple[list[float], int]:
    """In the window of ``fp`` (mask ``w``) of fault j: the delay of each path's first alarm, and how many paths
    had the alarm already on at the onset (a standing false alarm, not a detection)."""
    t, ftc = c.t, c.result.ftc
    hit_t, standing = [], 0
    if c.detect[j]:
        raised, on = alarms(ftc.fhat[:, :, j], c.thr[j], c.after)
        k0 = np.flatnonzero(t >= fp.start)
        for q in range(c.P):
            if len(k0) and k0[0] > 0 and on[q, k0[0] - 1]:
                standing += 1  # the alarm on at the onset: a standing false alarm, not a detection
                continue
            k = np.flatnonzero(w & raised[q])
            if len(k):
                hit_t.append(float(t[k[0]]) - fp.start)
    return hit_t, standing


def _window_from_arrays(c: _Run, fp, peaks: list[float]) -> tuple[dict, list]:
    """The window of ``fp``'s entry of the document (its intervals filled later), and the per-path numerators and
    denominators of its ratios."""
    result, t, e, dC_ftc, dC_no, P = c.result, c.t, c.e, c.dC_ftc, c.dC_no, c.P
    free, no, ftc = result.free, result.no_ftc, result.ftc
    p, lf = dC_ftc.shape[2], ftc.f.shape[2]
    j = list(result.names["faults"]).index(fp.fault)
    w = _mask(t, [(fp.start, fp.stop)])
    ws = _mask(t, [(fp.start, fp.stop)], SETTLE_FRACTION)
    on = onset_mask(t, fp.start)
    r = _rms_ratio(e[:, w, j], ftc.f[:, w, j])
    size = float(np.max(np.mean(np.abs(ftc.f[:, w, j]), axis=0))) if w.any() else 0.0
    peak = float(np.max(np.abs(ftc.f[:, w, j]))) if w.any() else None
    err = np.mean(np.abs(e[:, w, j]), axis=0) if w.any() else np.zeros(0)
    hit_t, standing = _detections(c, fp, j, w)
    tau = c.allow.tau
    allowed = min(3.0 * tau, fp.stop - fp.start) if math.isfinite(tau) else fp.stop - fp.start
    detect = c.detect[j]
    entry = {
        "fault": fp.fault, "start": float(fp.start), "stop": float(fp.stop),
        "fault_rel_rms_error": r,
        "fault_rel_rms_error_settled": _rms_ratio(e[:, ws, j], ftc.f[:, ws, j]),
        "settling_time": settling_time(err, size, t[w], fp.start),
        "release_time": _release(t, result.scenario, fp, np.mean(np.abs(e[:, :, j]), axis=0), size),
        "fault_peak": peak,
        "sensor_fault_peak_per_output": None if peak is None else [g[j] * peak for g in sensor_gains(result.design)],
        "ftc_true_ratio": _rms_ratio(dC_ftc[:, w], dC_no[:, w]) if r is not None else None,
        "ftc_true_ratio_per_output": [_rms_ratio(dC_ftc[:, w, k], dC_no[:, w, k]) if r is not None else None
                                      for k in range(p)],
        "ftc_true_rms_per_output": {
            "ftc": [float(np.sqrt(np.mean(dC_ftc[:, w, k] ** 2))) if w.any() else None for k in range(p)],
            "no_ftc": [float(np.sqrt(np.mean(dC_no[:, w, k] ** 2))) if w.any() else None for k in range(p)],
        },
        "ftc_compensated_ratio": _rms_ratio(ftc.yc[:, w] - free.y[:, w], no.y[:, w] - free.y[:, w]) if r is not None else None,
        "ftc_compensation_rms": [float(np.sqrt(np.mean(ftc.ucomp[:, w, i] ** 2))) if w.any() else None
                                 for i in range(ftc.u.shape[2])] if ftc.ucomp is not None else None,
        "onset_deviation": {
            run: float(np.sqrt(np.mean(np.sum(dC[:, on] ** 2, axis=(1, 2))))) if on.any() and w.any() else None
            for run, dC in (("ftc", dC_ftc), ("no_ftc", dC_no))
        },
        "crosstalk_peak": [
            None if q == j or not peaks[q] else float(np.max(np.abs(ftc.fhat[:, w, q]))) / peaks[q]
            for q in range(lf)
        ],
        "detection_delay": math.fsum(hit_t) / len(hit_t) if hit_t else None,
        "detection_delay_max": max(hit_t) if hit_t else None,
        "missed_detections": P - standing - len(hit_t) if detect else None,
        "standing_alarm_paths": standing if detect else None,
        "detection_probability": len(hit_t) / P if detect else None,
        "detection_probability_interval": clopper_pearson(len(hit_t), P) if detect else None,
        "detection_delay_allowed": float(allowed),
        "detection_probability_within": sum(1 for v in hit_t if v <= allowed + 1e-9 * max(abs(fp.stop), 1.0)) / P
        if detect else None,
        "input_saturation": input_saturation(ftc.u, result.design.input_limits, w),
    }  # fmt: skip
    pairs = [(_sq(e[:, w, j]), _sq(ftc.f[:, w, j])), (_sq(dC_ftc[:, w]), _sq(dC_no[:, w]))]
    pairs += [(_sq(dC_ftc[:, w, k]), _sq(dC_no[:, w, k])) for k in range(p)]
    pairs += [(_sq(ftc.yc[:, w] - free.y[:, w]), _sq(no.y[:, w] - free.y[:, w]))]
    return entry, pairs


def _after_window_from_arrays(c: _Run, w: int, entry: dict) -> list:
    """Set the ``after_window`` figures of window ``w`` (the scenario's order) in ``entry``, by their definition over
    the recorded samples (:func:`._reduce.after_window_entry`), and return the per-path pairs of its ratios."""
    from ._reduce import after_window_entry

    prof = [(fp.fault, float(fp.start), float(fp.stop)) for fp in c.result.scenario.faults]
    span = after_span(prof, w, float(c.result.T))
    a = (c.t >= span[0]) & (c.t < span[1])  # the same samples as _masks.after_mask
    p, ucomp = c.dC_ftc.shape[2], c.result.ftc.ucomp
    m = c.result.ftc.u.shape[2]
    both = a | _mask(c.t, [prof[w][1:]])  # the window and the span together
    sums = ([float(np.sum(c.dC_ftc[:, a, k] ** 2)) for k in range(p)],
            [float(np.sum(c.dC_no[:, a, k] ** 2)) for k in range(p)],
            None if ucomp is None else [float(np.sum(ucomp[:, a, i] ** 2)) for i in range(m)],
            (float(np.sum(c.dC_ftc[:, both] ** 2)), float(np.sum(c.dC_no[:, both] ** 2))))  # fmt: skip
    entry["after_window"] = after_window_entry(
        span, float(a.sum()) * c.P, sums, entry["fault_rel_rms_error"] is not None
    )
    return (
        [(_sq(c.dC_ftc[:, a]), _sq(c.dC_no[:, a]))]
        + [(_sq(c.dC_ftc[:, a, k]), _sq(c.dC_no[:, a, k])) for k in range(p)]
        + [(_sq(c.dC_ftc[:, both]), _sq(c.dC_no[:, both]))]
    )


def _outside_c_range(result: SimulationResult) -> dict:
    """The FTC run's measurements outside the range the generated C accepts (``outside_c_range*``; None where the
    design's step cannot be built for the recorded arrays)."""
    from ._c_range import accepted_measurements

    y = result.ftc.y
    try:
        lo, hi = accepted_measurements(result.design, result.dt)
    except Exception:  # noqa: BLE001 - arrays made by hand beside a design whose step does not fit them
        keys = ("c_accepted_range", "outside_c_range", "outside_c_range_per_output", "outside_c_range_paths")
        return {**dict.fromkeys(keys), "outside_c_range_first": None}
    out = (y < lo) | (y > hi)  # (paths, samples, outputs)
    hit = out.any(axis=2)
    first = [float(result.t[np.flatnonzero(h)[0]]) for h in hit if h.any()]
    return {
        "c_accepted_range": {"lo": [float(v) for v in lo], "hi": [float(v) for v in hi]},
        "outside_c_range": float(hit.mean()) if hit.size else 0.0,
        "outside_c_range_per_output": [
            float(np.mean(out[:, :, k])) if hit.size else 0.0 for k in range(y.shape[2])
        ],
        "outside_c_range_paths": len(first) / hit.shape[0] if hit.shape[0] else 0.0,
        "outside_c_range_first": min(first) if first else None,
    }


def _outside_region(result: SimulationResult) -> np.ndarray:
    """(paths, samples): is any state of any of the three runs outside the plant's region?"""
    xs = np.stack([result.free.x, result.no_ftc.x, result.ftc.x])
    if result.region is None:
        return np.zeros(xs.shape[1:3], bool)
    lo, hi = (np.asarray(v, dtype=float) for v in result.region)
    return np.any((xs < lo) | (xs > hi), axis=(0, 3))


def _where_it_ran(result: SimulationResult) -> dict:
    """Each state's extremes over the three runs (``state_range``: over the recorded paths and samples) and the
    plant's region (an open side null)."""
    xs = np.stack([result.free.x, result.no_ftc.x, result.ftc.x])
    return {"state_range": {"lo": xs.min(axis=(0, 1, 2)).tolist(), "hi": xs.max(axis=(0, 1, 2)).tolist()},
            "region": region_doc(result.region)}  # fmt: skip


def metrics(result: SimulationResult) -> dict:
    """The metrics document (docs/interface.md) of a run: the one the engine streamed over all its paths, or,
    for a result without it (the per-path engine), :func:`metrics_from_arrays`."""
    return dict(result.metrics) if result.metrics is not None else metrics_from_arrays(result)
