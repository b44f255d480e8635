"""Issue #20: the verdict thresholds on a metrics document are written once (fte_casadi.verdicts), and the
CLI's warnings, the tuner's choice and the structural explanations single out the same windows and faults."""

from __future__ import annotations

import ast
import importlib
import pathlib

import pytest

from fte_casadi import verdicts
from fte_casadi.cli import _warnings
from fte_casadi.design import limits
from fte_casadi.tune import search


@pytest.mark.slow
def test_every_consumer_reads_the_one_definition():
    metrics = importlib.import_module("fte_casadi.sim.metrics")  # (fte_casadi.sim.metrics is the function)
    for mod in (metrics, limits, search):
        for name in ("WORSE_THAN_NONE", "FALSE_ALARM"):
            assert getattr(mod, name) is getattr(verdicts, name), (
                mod.__name__,
                name,
            )  # imported, not rewritten
    root = pathlib.Path(verdicts.__file__).parent
    assigned = [
        f"{p.relative_to(root)}:{node.lineno}"
        for p in root.rglob("*.py")
        for node in ast.walk(ast.parse(p.read_text()))
        if isinstance(node, (ast.Assign, ast.AnnAssign))
        for t in (node.targets if isinstance(node, ast.Assign) else [node.target])
        if isinstance(t, ast.Name) and t.id in verdicts.__all__
    ]
    assert [a.split(":")[0] for a in assigned] == ["verdicts.py"] * 3, assigned  # written once


def _doc(ratio: float, false_alarm: float, faults) -> dict:
    return {
        "windows": [{"fault": faults[0], "start": 1.0, "stop": 3.0, "fault_rel_rms_error": 0.1,
                     "ftc_deviation_ratio": ratio, "input_saturation": [0.0]}],
        "false_alarm_rel_rms": [false_alarm] + [0.0] * (len(faults) - 1),
    }  # fmt: skip


@pytest.mark.parametrize("side", [-1, 1])
def test_warnings_choice_and_explanations_agree_at_the_thresholds(side, real_designs):
    d = real_designs["manipulator"]
    faults = list(d.names["faults"])
    ratio = verdicts.WORSE_THAN_NONE * (1 + side * 1e-3)
    fa = verdicts.FALSE_ALARM * (1 + side * 1e-3)
    m = _doc(ratio, fa, faults)
    warned = _warnings(m, list(d.names["inputs"]), faults)
    ftc_ok, fa_ok = search._admissible(m)
    explained = limits.explain_metrics(d, m)
    bad = side > 0
    assert sum("worse than none" in w for w in warned) == int(bad) and ftc_ok == (not bad)
    assert sum("false alarms" in w for w in warned) == int(bad) and fa_ok == (not bad)
    assert len(explained) == 2 * int(bad)  # one window, one fault explained above the thresholds, none below
