"""The Examples sections of the package's docstrings run and print what they say (``doctest``).

Every module of ``fte_casadi`` whose docstrings hold an example is found here, so an example added
anywhere runs in the suite; the examples that derive, design or generate C are marked slow.
"""

from __future__ import annotations

import doctest
import importlib
import pkgutil

import pytest

import fte_casadi

#: modules whose examples derive a T-S model, solve a design or generate and compile C (seconds each)
SLOW = {"fte_casadi.design._api", "fte_casadi.ts", "fte_casadi.codegen._generate", "fte_casadi.codegen._fmu"}


def _modules_with_examples() -> list[str]:
    out = []
    for info in pkgutil.walk_packages(fte_casadi.__path__, "fte_casadi."):
        if info.name.endswith("__main__"):
            continue
        spec = importlib.util.find_spec(info.name)
        origin = getattr(spec, "origin", None)
        if origin and origin.endswith(".py") and ">>> " in open(origin, encoding="utf-8").read():
            out.append(info.name)
    return sorted(out)


MODULES = _modules_with_examples()


def test_the_search_finds_the_examples():
    assert len(MODULES) >= 5 and "fte_casadi._rounding" in MODULES and SLOW <= set(MODULES)


@pytest.mark.parametrize(
    "name", [pytest.param(m, marks=pytest.mark.slow) if m in SLOW else m for m in MODULES]
)
def test_docstring_examples_run(name):
    module = importlib.import_module(name)
    flags = doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE
    result = doctest.testmod(module, optionflags=flags, verbose=False, report=True)
    assert result.attempted > 0, f"{name}: no example ran"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed (see above)"
