"""Built-in plants, written exactly as a user writes their own."""

from ._builtin import BUILTIN as BUILTIN
from ._builtin import SCENARIOS as SCENARIOS

# the face the other subpackages use: internal names, not in __all__ (docs/api.md: what is public)
from ._loader import load_plant as load_plant
from ._loader import load_scenario as load_scenario
from ._manipulator import manipulator as manipulator
from ._paper import PRINTED as PRINTED
from ._quadruple_tank import quadruple_tank as quadruple_tank
from ._three_tank import three_tank as three_tank

__all__ = ["BUILTIN", "SCENARIOS", "manipulator", "three_tank", "quadruple_tank"]
