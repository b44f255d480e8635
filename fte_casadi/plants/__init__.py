"""Built-in plants, written exactly as a user writes their own."""

from .manipulator import manipulator as manipulator
from .three_tank import three_tank as three_tank

BUILTIN = {"manipulator": manipulator, "three-tank": three_tank}
