"""The built-in plants and the paper's experiments, by name (``fte design manipulator``)."""

from __future__ import annotations

from ._manipulator import manipulator
from ._manipulator import scenario as _manipulator_scenario
from ._quadruple_tank import quadruple_tank
from ._quadruple_tank import scenario as _quadruple_tank_scenario
from ._three_tank import scenario as _three_tank_scenario
from ._three_tank import three_tank

__all__ = ["BUILTIN", "SCENARIOS"]

#: the built-in plants, by the name the commands take (functions returning a Plant)
BUILTIN = {"manipulator": manipulator, "three-tank": three_tank, "quadruple-tank": quadruple_tank}

#: the paper's experiments, by built-in plant name (functions returning a Scenario)
SCENARIOS = {
    "manipulator": _manipulator_scenario,
    "three-tank": _three_tank_scenario,
    "quadruple-tank": _quadruple_tank_scenario,
}
