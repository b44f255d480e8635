"""Accommodation after detection: a design that compensates a fault in the control only while it is detected.

The paper compensates every fault estimate at all times (``u = ... + Kf fhat``). During one fault, the
other faults' estimates show cross-talk (docs/interface.md, ``crosstalk_peak``), and ``Kf`` feeds it into
the plant: on a sensor fault, whose own column of ``Kf`` is zero, tolerant control can then leave the true
outputs worse than none. :func:`accommodated` returns the design with the gate of
:func:`fte_casadi.step.accommodation_gate`: fault j switches on in ``Kf fhat`` when ``|fhat_j|`` reaches its
detection threshold and its normalised residual ``r_j = |fhat_j| / threshold_j`` is the largest, and stays on
(hysteresis) until ``r_j`` falls below the release ratio (default :data:`RELEASE`) or another fault switches on
with a larger ratio; ``release=1`` is the memoryless gate. The thresholds are the detection thresholds of
:mod:`._detect`, calibrated on fault-free paths of the scenario.

The latches are state: they follow the observer state ``z`` in the step (``Design.nz``), so that the Python
step, the generated C and the FMU carry the same ones. The gate turns the closed loop into a switched system:
Theorems 1/5 certify the observer and each local controller, not the switching; only the Monte Carlo
measures it.
"""

from __future__ import annotations

import dataclasses

from ..design._record import Design
from ..errors import ParameterError
from ._engine import calibrate_detection

__all__ = ["accommodated"]

#: the default release ratio: a compensated fault is released when ``|fhat_j| / threshold_j`` falls below it
RELEASE = 0.5


def accommodated(design: Design, plant, scenario, *, paths: int, seed: int, false_alarm_rate: float | None = None,
                 dt: float | None = None, threads: int | None = None, release: float = RELEASE,
                 calibration_paths: int | None = None) -> Design:  # fmt: skip
    """``design`` with accommodation after detection, its thresholds calibrated at ``false_alarm_rate``
    (alarms per unit of the plant's time; default one per hour) on the fault-free paths that follow the run's
    ``paths`` (as many as the rate asks, or ``calibration_paths``; :func:`._engine.calibrate_detection`): the
    steady thresholds (the gate has no clock, so the start-up blocks' own thresholds are not used);
    ``release`` in (0, 1]: the ratio ``|fhat_j| / threshold_j`` below which a compensated fault is released
    (1: no hysteresis, the memoryless gate)."""
    if not (isinstance(release, (int, float)) and not isinstance(release, bool) and 0 < release <= 1):
        raise ParameterError(
            f"the release ratio must be a number in (0, 1] (1: no hysteresis); got {release!r}"
        )
    if plant.lf < 1:
        raise ParameterError(f"{plant.name}: the plant has no faults to accommodate")
    cal = calibrate_detection(design, plant, scenario, paths=paths, seed=seed, false_alarm_rate=false_alarm_rate,
                              dt=dt, threads=threads, calibration_paths=calibration_paths)  # fmt: skip
    thr, entries = cal.thresholds, cal.entries
    bad = [e["fault"] for e, v in zip(entries, thr) if not (v > 0 and v < float("inf"))]
    if bad:
        raise ParameterError(
            f"no detection threshold could be set for {', '.join(bad)} (fault-free estimates identically zero, or too "
            "few calibration paths): accommodation needs a positive finite threshold per fault"
        )
    acc = {
        "rule": "isolate",
        "thresholds": [float(v) for v in thr],
        "release": float(release),
        "false_alarm_rate": entries[0]["false_alarm_rate_asked"],
        "calibration": {
            "paths": entries[0]["calibration_paths"],
            "seed": int(seed),
            "scenario": scenario.name,
        },
    }
    listed = ", ".join(f"{e['fault']} {v:.4g}" for e, v in zip(entries, thr))
    held = ("memoryless" if release >= 1 else
            f"held until |fhat| / threshold < {float(release):g} or another fault switches on")  # fmt: skip
    note = (f"accommodation after detection: a fault is compensated only while detected and isolated (thresholds "
            f"{listed}, calibrated on "
            f"{entries[0]['calibration_paths']} fault-free paths; {held})")  # fmt: skip
    return dataclasses.replace(design, accommodation=acc, status=[*design.status, note])
