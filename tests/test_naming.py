"""One name per concept: the observer/controller's sample time is ``sample_time`` in the code, ``ts`` is
only ever a T-S model, ``dt`` is the simulation's step and lives in ``sim/`` (see :mod:`fte_casadi.sim`).
The former keywords (``ts=``, ``dt=``, ``default_ts``) were removed in 0.2.0: giving one is a TypeError."""

from __future__ import annotations

import ast
import pathlib

import numpy as np
import pytest

import fte_casadi.codegen
from fte_casadi.codegen import generate_c
from fte_casadi.step import step_function

ROOT = pathlib.Path(__file__).resolve().parents[1] / "fte_casadi"
#: where ``dt`` (the simulation's step) may be a name: the simulator, the CLI's ``fte simulate --dt``, and
#: the memory a simulation run will take (_resources.py), and the benchmarks of the simulator (bench/)
DT_HOMES = ("sim/", "cli/", "_resources.py", "bench/")
#: calls whose keyword ``dt`` is the simulation's step (a plant's scenario, a simulation run)
DT_CALLEES = ("Scenario", "simulate", "sweep")
#: names the sample time had besides ``sample_time`` (``ts_max`` stays: the design document's key)
FORMER = {"tsf", "tsm", "_check_ts", "design_step", "_scenario_dt"}


def _trees():
    for path in sorted(ROOT.rglob("*.py")):
        yield path.relative_to(ROOT).as_posix(), ast.parse(path.read_text())


def _names(tree) -> list[tuple[str, int]]:
    """Every name the module binds or reads (variables, parameters, functions), with its line."""
    out = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Name):
            out.append((node.id, node.lineno))
        elif isinstance(node, ast.arg):
            out.append((node.arg, node.lineno))
        elif isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.append((node.name, node.lineno))
        elif isinstance(node, ast.Call):
            callee = ast.unparse(node.func).split(".")[-1]
            out += [(k.arg, k.value.lineno) for k in node.keywords if k.arg and callee not in DT_CALLEES]
    return out


@pytest.mark.slow
def test_the_scan_sees_the_package():
    trees = dict(_trees())
    assert len(trees) > 50 and "sim/_engine.py" in trees and "step.py" in trees
    # and it would see a sample time called dt or ts: the simulator does call its step dt
    assert any(n == "dt" for n, _ in _names(trees["sim/_engine.py"]))


@pytest.mark.slow
def test_dt_is_a_name_only_in_the_simulator():
    bad = [
        f"{rel}:{line}"
        for rel, tree in _trees()
        if not rel.startswith(DT_HOMES)
        for name, line in _names(tree)
        if name == "dt"
    ]
    assert bad == [], f"'dt' outside sim/ (the sample time is 'sample_time'): {bad}"


@pytest.mark.slow
def test_ts_is_never_a_number():
    """``ts`` is a T-S model: never annotated as a number, never in arithmetic, never converted to float,
    never a keyword of a call."""
    bad = []
    for rel, tree in _trees():
        for node in ast.walk(tree):
            if isinstance(node, ast.arg) and node.arg == "ts" and node.annotation is not None:
                if ast.unparse(node.annotation) != "TSModel":
                    bad.append(f"{rel}:{node.lineno} ts: {ast.unparse(node.annotation)}")
            elif isinstance(node, ast.BinOp) and any(
                isinstance(v, ast.Name) and v.id == "ts" for v in (node.left, node.right)
            ):
                bad.append(f"{rel}:{node.lineno} {ast.unparse(node)}")
            elif isinstance(node, ast.Call) and any(
                isinstance(a, ast.Name) and a.id == "ts" for a in node.args
            ):
                if ast.unparse(node.func) in ("float", "int", "abs", "repr"):
                    bad.append(f"{rel}:{node.lineno} {ast.unparse(node)}")
            elif isinstance(node, ast.keyword) and node.arg == "ts":
                bad.append(f"{rel}:{node.value.lineno} ts=")
    assert bad == [], bad


@pytest.mark.slow
def test_former_names_of_the_sample_time_are_gone():
    bad = [f"{rel}:{line} {name}" for rel, tree in _trees() for name, line in _names(tree) if name in FORMER]
    assert bad == [], bad


@pytest.mark.slow
def test_the_former_default_ts_is_gone():
    uses = [(rel, name) for rel, tree in _trees() for name, _ in _names(tree) if name == "default_ts"]
    assert uses == [] and not hasattr(fte_casadi.codegen, "default_ts")


def test_the_scan_would_catch_a_sample_time_called_ts_or_dt():
    tree = ast.parse("def f(ts: float, dt):\n    return ts * 2 + float(ts)\n")
    names = [n for n, _ in _names(tree)]
    assert "dt" in names and "ts" in names
    assert any(isinstance(n, ast.BinOp) and ast.unparse(n.left) == "ts" for n in ast.walk(tree))


@pytest.fixture(scope="module")
def design(real_designs):
    return real_designs["three-tank"]


def test_step_function_refuses_the_former_keyword(design):
    z, y = np.linspace(-1, 1, design.nbar), np.asarray(design.C) @ np.full(int(design.dims.n), 0.3)
    new = [np.array(v) for v in step_function(design, sample_time=0.01)(z, y)]
    other = [np.array(v) for v in step_function(design, sample_time=0.02)(z, y)]
    assert not np.array_equal(new[0], other[0])  # the keyword does reach the step
    with pytest.raises(TypeError, match="ts"):
        step_function(design, ts=0.01)


def test_generate_c_refuses_the_former_keyword(design, tmp_path):
    generate_c(design, tmp_path / "new", sample_time=0.005)
    assert (
        "#define FTE_THREE_TANK_TS (0.005)" in (tmp_path / "new" / "fte_three_tank.h").read_text()
    )  # as asked
    with pytest.raises(TypeError, match="ts"):
        generate_c(design, tmp_path / "old", ts=0.005)


@pytest.mark.slow
def test_to_control_refuses_the_former_keyword(design):
    pytest.importorskip("control")
    assert design.to_control(1, 1, sample_time=0.01).dt == 0.01
    with pytest.raises(TypeError, match="dt"):
        design.to_control(1, 1, dt=0.01)
