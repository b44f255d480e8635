"""The parts of a source checkout that are not in the wheel.

The benchmarks (``fte bench``: the design against the 0.1 design, the vectorised Monte Carlo engine
against the per-path engine, the generated C step against hand-written C) live in the repository's
top-level ``benchmarks/`` package beside ``fte_casadi/``; the wheel holds ``fte_casadi`` only.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path
from types import ModuleType

from .errors import MissingDependencyError

__all__ = ["load_benchmarks"]


def load_benchmarks() -> ModuleType:
    """The ``benchmarks`` package of the checkout this ``fte_casadi`` runs from.

    Already imported (``python -m pytest`` from the checkout), it is returned as is; else it is
    loaded from ``benchmarks/`` next to the ``fte_casadi/`` folder (an editable install, or
    ``python -m fte_casadi`` in the checkout).

    Raises
    ------
    MissingDependencyError
        ``fte_casadi`` is installed from a wheel, without the benchmarks.
    """
    mod = sys.modules.get("benchmarks")
    if mod is not None and hasattr(mod, "run_all"):
        return mod
    init = Path(__file__).resolve().parents[1] / "benchmarks" / "__init__.py"
    if not init.is_file():
        raise MissingDependencyError(
            "the benchmarks (the 0.1 design, the per-path Monte Carlo engine, hand-written C, sdeint) "
            "ship with the source repository, not with the installed package: run `fte bench` from a "
            "checkout (git clone the repository, then `pip install -e '.[bench]'` in it)"
        )
    spec = importlib.util.spec_from_file_location(
        "benchmarks", init, submodule_search_locations=[str(init.parent)]
    )
    mod = importlib.util.module_from_spec(spec)
    sys.modules["benchmarks"] = mod
    try:
        spec.loader.exec_module(mod)
    except BaseException:
        del sys.modules["benchmarks"]
        raise
    return mod
