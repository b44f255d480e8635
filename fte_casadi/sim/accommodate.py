"""Accommodation after detection: a design that compensates a fault in the control only while it is detected.

The paper compensates every fault estimate at all times (``u = ... + Kf fhat``). During one fault, the
other faults' estimates show cross-talk (docs/interface.md, ``crosstalk_peak``), and ``Kf`` feeds it into
the plant: on a sensor fault, whose own column of ``Kf`` is zero, tolerant control can then leave the true
outputs worse than none. :func:`accommodated` returns the design with the gate of
:func:`fte_casadi.step.accommodation_gate`: fault j enters ``Kf fhat`` only while ``|fhat_j|`` reaches its
detection threshold and its normalised residual ``|fhat_j| / threshold_j`` is the largest. The thresholds are
the detection thresholds of :mod:`.detect`, calibrated on fault-free paths of the scenario.

The gate is memoryless (no hysteresis), so that the Python step, the generated C and the FMU compute it from
the same sample. It turns the closed loop into a switched system: Theorems 1/5 certify the observer and
each local controller, not the switching; only the Monte Carlo measures it.
"""

from __future__ import annotations

import dataclasses

from ..design.record import Design
from ..errors import ParameterError
from .engine import calibrate_thresholds

__all__ = ["accommodated"]


def accommodated(design: Design, plant, scenario, *, paths: int, seed: int, false_alarm_rate: float | None = None,
                 dt: float | None = None, threads: int | None = None) -> Design:  # fmt: skip
    """``design`` with accommodation after detection, its thresholds calibrated at ``false_alarm_rate``
    (alarms per unit of the plant's time; default one per hour) on ``max(paths, 8)`` fault-free paths."""
    if plant.lf < 1:
        raise ParameterError(f"{plant.name}: the plant has no faults to accommodate")
    thr, entries = calibrate_thresholds(design, plant, scenario, paths=paths, seed=seed,
                                        false_alarm_rate=false_alarm_rate, dt=dt, threads=threads)  # fmt: skip
    bad = [e["fault"] for e, v in zip(entries, thr) if not (v > 0 and v < float("inf"))]
    if bad:
        raise ParameterError(
            f"no detection threshold could be set for {', '.join(bad)} (fault-free estimates identically zero, or too "
            "few calibration paths): accommodation needs a positive finite threshold per fault"
        )
    acc = {
        "rule": "isolate",
        "thresholds": [float(v) for v in thr],
        "false_alarm_rate": entries[0]["false_alarm_rate_asked"],
        "calibration": {
            "paths": entries[0]["calibration_paths"],
            "seed": int(seed),
            "scenario": scenario.name,
        },
    }
    listed = ", ".join(f"{e['fault']} {v:.4g}" for e, v in zip(entries, thr))
    note = (f"accommodation after detection: a fault is compensated only while detected and isolated (thresholds "
            f"{listed}, calibrated on "
            f"{entries[0]['calibration_paths']} fault-free paths)")  # fmt: skip
    return dataclasses.replace(design, accommodation=acc, status=[*design.status, note])
