"""Embedded C of the discrete observer/controller step (docs/interface.md, "Generated C")."""

from ._build import compile_program as compile_program
from ._build import compile_shared as compile_shared
from ._build import find_compiler as find_compiler
from ._fmu import generate_fmu as generate_fmu
from ._generate import default_sample_time as default_sample_time
from ._generate import generate_c as generate_c
from ._generate import output_files as output_files

__all__ = [
    "generate_c",
    "default_sample_time",
    "output_files",
    "generate_fmu",
    "find_compiler",
    "compile_shared",
    "compile_program",
]
