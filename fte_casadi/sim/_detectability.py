"""The smallest fault a design can see: per fault, the detection probability against the fault's size.

Each fault runs alone (the scenario's other faults absent) at several factors of its size on one compiled
engine (the sweep's machinery: the faults' coefficients are runtime inputs, no recompilation), with one
calibration of the thresholds (the fault-free behaviour does not depend on the faults). At each factor a
fault's detection probability is the share of its windows' (path, window) pairs on which the alarm rose
within the allowed delay of the onset (``detection_delay_allowed``: three observer time constants, at most
the window), its size the largest ``fault_peak`` of its windows. The factors are found in steps of four, from
the factor at which the fault's size equals its threshold, until the probability crosses :data:`TARGET`
(95 %), then halving the bracket in ``log(factor)`` :data:`REFINE` times; the minimum detectable fault is the
size, linearly interpolated in ``log(factor)`` between the bracket's ends, from which every factor tried
detects at least ``TARGET``. It is a Monte Carlo figure over ``paths`` paths: each point carries its exact
binomial interval.
"""

from __future__ import annotations

import math

from ..errors import ParameterError
from ._engine import (
    Prepared,
    _check_settings,
    _scales,
    calibrate_detection,
    check_scenario,
    resolve_dt,
    simulate,
)
from ._intervals import clopper_pearson

__all__ = ["detectability"]  # public: docs/api.md

#: the detection probability the minimum detectable fault reaches
TARGET = 0.95
#: the search's steps in log2(factor), then the bisection steps after the bracket is found (the factor's
#: resolution is STEP 2^-REFINE in log2)
STEP = 2
REFINE = 2
#: the factors tried at most: 2^-LOWEST .. 2^HIGHEST
LOWEST, HIGHEST = 10, 4


def _point(metrics: dict, fault: str) -> tuple[float, int, float | None, float | None]:
    """(detected within the allowed delay, trials, the fault's size, the allowed delay) of ``fault``."""
    hits, n, size, delay = 0.0, 0, None, None
    P = int(metrics["paths"])
    for w in metrics["windows"]:
        if w["fault"] != fault or w.get("detection_probability_within") is None:
            continue
        hits += w["detection_probability_within"] * P
        n += P
        if w.get("fault_peak") is not None:
            size = max(size or 0.0, float(w["fault_peak"]))
        delay = w.get("detection_delay_allowed")
    return hits, n, size, delay


def detectability(design, plant, scenario, *, paths: int = 64, seed: int = 0, dt: float | None = None,
                  scales: dict | None = None, false_alarm_rate: float | None = None,
                  calibration_paths: int | None = None, threads: int | None = None, prepared: Prepared | None = None,
                  exact: bool = True, calibration=None) -> dict:  # fmt: skip
    """Per fault of ``scenario``: the detection probability against the fault's size, and the minimum
    detectable fault (module docstring).

    ``scales``: the other factors (``noise_scale``, ``d_scale``, ``measurement_noise_scale``) held fixed;
    ``fault_scale`` is what varies. ``calibration``: thresholds calibrated before for the same fault-free
    behaviour (:func:`._engine.calibrate_detection`; the same design, scenario, step and factors). Returns ``{"paths", "seed", "target", "measurement_noise_scale",
    "calibration": the detection entries, "curves": [{"fault", "delay", "factor", "size", "probability",
    "interval", "min_detectable_fault", "min_detectable_factor", "why"}]}``, the points in increasing factor.
    """
    _check_settings(design, plant, paths, seed, dt)
    check_scenario(plant, scenario)
    base = {k: v for k, v in (scales or {}).items() if k != "fault_scale"}
    if scales and "fault_scale" in scales:
        raise ParameterError("detectability varies fault_scale itself; leave it out of scales")
    sc = _scales(base, scenario)
    dt, nsteps, _ = resolve_dt(design, scenario, dt)
    prep = prepared or Prepared(
        design, plant, scenario, dt, nsteps, _scales(None, scenario), exact=bool(exact)
    )
    prep = prep.rescaled({**sc, "fault_scale": prep.scales["fault_scale"]})
    cal = calibration or calibrate_detection(design, plant, scenario, paths=paths, seed=seed,
                                             false_alarm_rate=false_alarm_rate, threads=threads, prepared=prep,
                                             calibration_paths=calibration_paths)  # fmt: skip
    names = list(plant.fault_names)
    faults = [nm for nm in names if any(fp.fault == nm for fp in scenario.faults)]
    seen: dict[tuple[str, float], dict] = {}

    def allowed(fault: str, factor: float) -> bool:
        try:
            for fp in scenario.faults:
                if fp.fault == fault:
                    fp.check_scale(factor)
        except ParameterError:
            return False
        return True

    def run(k: float, fault: str) -> dict:
        """The scenario with ``fault`` alone, at 2^k times its size (the other faults absent)."""
        factor = float(2.0**k)
        if (fault, factor) not in seen:
            f = [factor if nm == fault else 0.0 for nm in names]
            res = simulate(design, plant, scenario, paths=paths, seed=seed, dt=dt, progress=False, record_paths=0,
                           threads=threads, scales=sc, prepared=prep.with_fault_factors(f), exact=bool(exact),
                           calibration=cal)  # fmt: skip
            seen[(fault, factor)] = res.metrics
        return seen[(fault, factor)]

    def prob(k: float, fault: str) -> float:
        hits, n, _, _ = _point(run(k, fault), fault)
        return hits / n if n else math.nan

    thr = {e["fault"]: e.get("threshold") for e in cal.entries}
    brackets = {}
    for fault in faults:
        k_max = HIGHEST  # the largest power of two the fault accepts (a loss is at most 100 %)
        while k_max > 0 and not allowed(fault, 2.0**k_max):
            k_max -= 1
        _, _, size, _ = _point(run(0.0, fault), fault)
        # first guess: the factor at which the fault's size is its threshold (the estimate follows the fault)
        guess = math.log2(thr[fault] / size) if thr.get(fault) and size else 0.0
        k = float(min(max(round(guess), -LOWEST), k_max))
        if prob(k, fault) >= TARGET:
            while k > -LOWEST and prob(max(k - STEP, -LOWEST), fault) >= TARGET:
                k = max(k - STEP, -LOWEST)
            brackets[fault] = (max(k - STEP, -LOWEST), k) if k > -LOWEST else (None, k)
        else:
            while k < k_max and prob(min(k + STEP, k_max), fault) < TARGET:
                k = min(k + STEP, k_max)
            brackets[fault] = (k, min(k + STEP, k_max)) if k < k_max else (k, None)
    for _ in range(REFINE):
        for fault, (lo, hi) in brackets.items():
            if lo is None or hi is None:
                continue
            mid = 0.5 * (lo + hi)
            brackets[fault] = (mid, hi) if prob(mid, fault) < TARGET else (lo, mid)
    curves = []
    for fault in faults:
        ks = sorted(f for nm, f in seen if nm == fault)
        pts = [(f, *_point(seen[(fault, f)], fault)) for f in ks]
        factor = [p[0] for p in pts]
        probability = [p[1] / p[2] if p[2] else None for p in pts]
        interval = [clopper_pearson(int(round(p[1])), p[2]) if p[2] else None for p in pts]
        size = [p[3] for p in pts]
        delay = next((p[4] for p in pts if p[4] is not None), None)
        mdf, mfac, why = _minimum(factor, probability, size)
        curves.append({"fault": fault, "delay": delay, "factor": factor, "size": size, "probability": probability,
                       "interval": interval, "min_detectable_fault": mdf, "min_detectable_factor": mfac,
                       "why": why})  # fmt: skip
    return {
        "paths": int(paths),
        "seed": int(seed),
        "target": TARGET,
        "measurement_noise_scale": sc["measurement_noise_scale"],
        "measurement_noise": None
        if scenario.measurement_noise is None
        else scenario.measurement_noise.reported(sc["measurement_noise_scale"]),
        "calibration": cal.entries,
        "curves": curves,
    }


def _minimum(factor, probability, size) -> tuple[float | None, float | None, str | None]:
    """The size from which every factor tried detects at least TARGET, interpolated in log(factor) between the
    last factor below it and the first at or above it; None (and why) when no factor reaches it."""
    ok = [p is not None and p >= TARGET for p in probability]
    if not ok or not ok[-1]:
        return (
            None,
            None,
            f"not detected on {100 * TARGET:g} % of the paths at the largest factor tried ({factor[-1]:g})",
        )
    i = len(ok) - 1
    while i > 0 and ok[i - 1]:
        i -= 1
    if i == 0:
        return (size[0], factor[0],
                f"detected on {100 * TARGET:g} % of the paths already at the smallest factor tried ({factor[0]:g}): "
                "an upper bound")  # fmt: skip
    a, b = math.log(factor[i - 1]), math.log(factor[i])
    pa, pb = probability[i - 1], probability[i]
    u = (TARGET - pa) / (pb - pa) if pb != pa else 1.0
    f = math.exp(a + u * (b - a))
    sa, sb = size[i - 1], size[i]
    s = (
        None
        if sa is None or sb is None or sa <= 0 or sb <= 0
        else math.exp(math.log(sa) + u * (math.log(sb) - math.log(sa)))
    )
    return s, f, None


def attach(metrics: dict, sets: list[dict], noise_scale: float = 1.0) -> dict:
    """``metrics`` with ``detectability`` (the curves of ``sets``) and each ``detection`` entry's
    ``min_detectable_fault`` from the set measured at the run's own measurement noise (``noise_scale``)."""
    out = dict(metrics)
    out["detectability"] = sets
    own = next((s for s in sets if s["measurement_noise_scale"] == noise_scale), sets[0] if sets else None)
    mdf = {c["fault"]: c["min_detectable_fault"] for c in (own or {}).get("curves", [])}
    out["detection"] = [{**e, "min_detectable_fault": mdf.get(e["fault"], e.get("min_detectable_fault"))}
                        for e in out.get("detection") or []]  # fmt: skip
    return out
