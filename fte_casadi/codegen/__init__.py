"""Embedded C of the discrete observer/controller step (docs/interface.md, "Generated C")."""

from ._build import compile_program as compile_program
from ._build import compile_shared as compile_shared
from ._build import find_compiler as find_compiler

# the face the other subpackages use: internal names, not in __all__ (docs/api.md: what is public)
from ._ctypes_step import CStep as CStep
from ._ctypes_step import closed_loop_compare as closed_loop_compare
from ._fmu import check_fmu_target as check_fmu_target
from ._fmu import generate_c_and_fmu as generate_c_and_fmu
from ._fmu import generate_fmu as generate_fmu
from ._generate import BUILTIN_DIRS as BUILTIN_DIRS
from ._generate import default_sample_time as default_sample_time
from ._generate import file_mode as file_mode
from ._generate import generate_c as generate_c
from ._generate import memory_report as memory_report
from ._generate import output_files as output_files
from ._generate import output_range as output_range
from ._generate import prepare_dir as prepare_dir

__all__ = [
    "generate_c",
    "default_sample_time",
    "output_files",
    "generate_fmu",
    "find_compiler",
    "compile_shared",
    "compile_program",
]
