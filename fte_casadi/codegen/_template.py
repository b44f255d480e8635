"""The hand-written C around the CasADi-generated step: template files read and filled.

CasADi writes the maths into ``fte_NAME_casadi.c``/``.h``; the files of ``templates/`` write the rest
(docs/interface.md, "Generated C"), filled with :class:`string.Template` (``${name}`` placeholders,
``$$`` for a dollar sign):

- ``fte_NAME.h.in``, ``fte_NAME.c.in``: the wrapper ``fte_NAME.h``/``.c`` (types, sizes, the two
  calls; input check, argument plumbing, state update), plain C99 with no library call at all
  (``<stdint.h>`` for the bit test of a NaN or an infinity);
- ``README.md.in``: the README of the generated folder;
- ``MID_fmi2.c.in``: the FMI 2.0 co-simulation wrapper of an FMU (:mod:`._fmu`), the only file of the
  FMU that calls the C library (``vsnprintf`` for the log messages, ``strlen``/``memcpy``/``memset``);
  instance memory comes from the environment's ``allocateMemory`` callback;
- ``fte_fmi2.h``: the declarations of the FMI 2.0 C API that wrapper needs (types, callbacks, the common
  and the co-simulation functions), written for fte_casadi from the FMI 2.0 standard's interface
  (ABI-compatible with the standard's fmi2Functions.h, platform "default"), copied as it is. An
  importer that compiles the sources for static linking defines FMI2_FUNCTION_PREFIX, as with the
  standard headers.

The templates ship in the wheel as package data.
"""

from __future__ import annotations

import functools
from importlib.resources import files
from string import Template

from ..errors import CodegenError

__all__ = ["read", "fill", "TEMPLATES"]

#: the template files, by what they write
TEMPLATES = {
    "header": "fte_NAME.h.in",
    "source": "fte_NAME.c.in",
    "readme": "README.md.in",
    "fmu_wrapper": "MID_fmi2.c.in",
    "fmi2_header": "fte_fmi2.h",
}


@functools.cache
def read(name: str) -> str:
    """The text of the template file ``name`` of ``templates/`` (bytes as written, UTF-8)."""
    try:
        return files(__package__).joinpath("templates", name).read_bytes().decode("utf-8")
    except FileNotFoundError:
        raise CodegenError(
            f"the C template {name!r} is missing from {files(__package__).joinpath('templates')}; "
            "the package is incomplete: reinstall fte_casadi"
        ) from None


def fill(name: str, values: dict) -> str:
    """The template file ``name`` with every ``${key}`` replaced by ``values[key]``.

    Raises
    ------
    CodegenError
        When the template names a placeholder that ``values`` lacks.
    """
    try:
        return Template(read(name)).substitute(values)
    except KeyError as exc:
        raise CodegenError(
            f"the C template {name!r} needs a value for ${{{exc.args[0]}}}, which was not given"
        ) from None
