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


class _Probe:
    """The runs of :func:`detectability`: the scenario with one fault alone at ``2^k`` times its size (the other
    faults absent), each run once and kept in ``seen`` by ``(fault, factor)``."""

    def __init__(self, design, plant, scenario, sc, prep, cal, paths, seed, dt, threads, exact):
        self.design, self.plant, self.scenario, self.sc, self.prep, self.cal = (
            design,
            plant,
            scenario,
            sc,
            prep,
            cal,
        )
        self.paths, self.seed, self.dt, self.threads, self.exact = paths, seed, dt, threads, exact
        self.names = list(plant.fault_names)
        self.seen: dict[tuple[str, float], dict] = {}

    def allowed(self, fault: str, factor: float) -> bool:
        """Does every window of ``fault`` accept ``factor`` (a loss is at most 100 %)?"""
        try:
            for fp in self.scenario.faults:
                if fp.fault == fault:
                    fp.check_scale(factor)
        except ParameterError:
            return False
        return True

    def run(self, k: float, fault: str) -> dict:
        """The metrics of the scenario with ``fault`` alone, at 2^k times its size (the other faults absent)."""
        factor = float(2.0**k)
        if (fault, factor) not in self.seen:
            f = [factor if nm == fault else 0.0 for nm in self.names]
            res = simulate(self.design, self.plant, self.scenario, paths=self.paths, seed=self.seed, dt=self.dt,
                           progress=False, record_paths=0, threads=self.threads, scales=self.sc,
                           prepared=self.prep.with_fault_factors(f), exact=bool(self.exact),
                           calibration=self.cal)  # fmt: skip
            self.seen[(fault, factor)] = res.metrics
        return self.seen[(fault, factor)]

    def prob(self, k: float, fault: str) -> float:
        hits, n, _, _ = _point(self.run(k, fault), fault)
        return hits / n if n else math.nan


def _bracket(probe: _Probe, fault: str, threshold) -> tuple:
    """``(lo, hi)``: exponents k of the fault's factor ``2^k`` with the detection probability below and at or above
    :data:`TARGET` (None where the range of factors ends first), walked from the factor at which the fault's size
    is its threshold."""
    k_max = HIGHEST  # the largest power of two the fault accepts (a loss is at most 100 %)
    while k_max > 0 and not probe.allowed(fault, 2.0**k_max):
        k_max -= 1
    _, _, size, _ = _point(probe.run(0.0, fault), fault)
    # first guess: the factor at which the fault's size is its threshold (the estimate follows the fault)
    guess = math.log2(threshold / size) if threshold and size else 0.0
    k = float(min(max(round(guess), -LOWEST), k_max))
    if probe.prob(k, fault) >= TARGET:
        while k > -LOWEST and probe.prob(max(k - STEP, -LOWEST), fault) >= TARGET:
            k = max(k - STEP, -LOWEST)
        return (max(k - STEP, -LOWEST), k) if k > -LOWEST else (None, k)
    while k < k_max and probe.prob(min(k + STEP, k_max), fault) < TARGET:
        k = min(k + STEP, k_max)
    return (k, min(k + STEP, k_max)) if k < k_max else (k, None)


def _curve(seen: dict, fault: str) -> dict:
    """The fault's points (in increasing factor): the detection probability and its interval against the size,
    the delay, and the minimum detectable fault."""
    ks = sorted(f for nm, f in seen if nm == fault)
    pts = [(f, *_point(seen[(fault, f)], fault)) for f in ks]
    factor = [p[0] for p in pts]
    probability = [p[1] / p[2] if p[2] else None for p in pts]
    interval = [clopper_pearson(int(round(p[1])), p[2]) if p[2] else None for p in pts]
    size = [p[3] for p in pts]
    delay = next((p[4] for p in pts if p[4] is not None), None)
    mdf, mfac, why = _minimum(factor, probability, size)
    return {"fault": fault, "delay": delay, "factor": factor, "size": size, "probability": probability,
            "interval": interval, "min_detectable_fault": mdf, "min_detectable_factor": mfac, "why": why}  # fmt: skip


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
    probe = _Probe(design, plant, scenario, sc, prep, cal, paths, seed, dt, threads, exact)
    faults = [nm for nm in plant.fault_names if any(fp.fault == nm for fp in scenario.faults)]
    thr = {e["fault"]: e.get("threshold") for e in cal.entries}
    brackets = {fault: _bracket(probe, fault, thr.get(fault)) for fault in faults}
    for _ in range(REFINE):
        for fault, (lo, hi) in brackets.items():
            if lo is None or hi is None:
                continue
            mid = 0.5 * (lo + hi)
            brackets[fault] = (mid, hi) if probe.prob(mid, fault) < TARGET else (lo, mid)
    curves = [_curve(probe.seen, fault) for fault in faults]
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
