"""The C compiler, and where compiled libraries are kept.

One lookup for every part that compiles C: the Monte Carlo engine (:mod:`fte_casadi.sim._vector`),
the build helpers of the generated code (:mod:`fte_casadi.codegen._build`) and the benchmarks.
"""

from __future__ import annotations

import os
import shutil
from pathlib import Path

__all__ = ["find_compiler", "cache_dir"]

_CANDIDATES = ("cc", "gcc", "clang")


def find_compiler() -> str | None:
    """Path of a C compiler: ``$CC`` when set, else the first of cc, gcc, clang on PATH; None if none."""
    env = os.environ.get("CC")
    if env:
        found = shutil.which(env)
        if found:
            return found
    for name in _CANDIDATES:
        found = shutil.which(name)
        if found:
            return found
    return None


def cache_dir() -> Path:
    """Where compiled closed loops are kept: ``$FTE_CACHE_DIR``, else ``$XDG_CACHE_HOME/fte_casadi``,
    else ``~/.cache/fte_casadi``. The engine hashes the C it generates into the file name, so a closed
    loop compiled once loads in milliseconds afterwards."""
    base = os.environ.get("FTE_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fte_casadi"
