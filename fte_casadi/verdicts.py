"""The verdicts on a metrics document (docs/interface.md), in one place.

``fte simulate`` warns by them, the report marks by them, ``fte tune`` chooses by them and
:func:`fte_casadi.design.limits.explain_metrics` explains the windows and faults they single out.
A module of its own (as :mod:`fte_casadi.rounding`), so that every step of the package can read them
without importing the simulator.
"""

from __future__ import annotations

__all__ = ["WORSE_THAN_NONE", "FALSE_ALARM", "SATURATED"]

#: an FTC deviation ratio above this: tolerant control leaves the outputs worse than none (below it:
#: better than none)
WORSE_THAN_NONE = 1.0
#: a fault estimate outside its windows above this fraction of the fault's RMS: false alarms
FALSE_ALARM = 1.0
#: an input at a limit for more than this fraction of a window: the tolerance is that of a saturated actuator
SATURATED = 0.05
