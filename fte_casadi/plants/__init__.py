"""Built-in plants, written exactly as a user writes their own."""

from ._manipulator import manipulator as manipulator
from ._quadruple_tank import quadruple_tank as quadruple_tank
from ._three_tank import three_tank as three_tank

BUILTIN = {"manipulator": manipulator, "three-tank": three_tank, "quadruple-tank": quadruple_tank}

from ._manipulator import scenario as _manipulator_scenario  # noqa: E402
from ._quadruple_tank import scenario as _quadruple_tank_scenario  # noqa: E402
from ._three_tank import scenario as _three_tank_scenario  # noqa: E402

#: the paper's experiments, by built-in plant name (functions returning a Scenario)
SCENARIOS = {
    "manipulator": _manipulator_scenario,
    "three-tank": _three_tank_scenario,
    "quadruple-tank": _quadruple_tank_scenario,
}
