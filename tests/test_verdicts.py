"""Issue #20: the verdict thresholds on a metrics document are written once (fte_casadi.verdicts), and the
CLI's warnings, the tuner's choice and the structural explanations single out the same windows and faults."""

from __future__ import annotations

import ast
import importlib
import pathlib

import pytest

from fte_casadi import verdicts
from fte_casadi.cli._simulate import _warnings
from fte_casadi.design import _limits as limits
from fte_casadi.tune import _search as search


@pytest.mark.slow
def test_every_consumer_reads_the_one_definition():
    metrics = importlib.import_module("fte_casadi.sim._metrics")  # (fte_casadi.sim.metrics is the function)
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
    consts = [n for n in verdicts.__all__ if n.isupper()]
    assert [a.split(":")[0] for a in assigned] == ["verdicts.py"] * len(consts), assigned  # written once


def _doc(ratio: float, false_alarm: float, faults) -> dict:
    return {
        "windows": [{"fault": faults[0], "start": 1.0, "stop": 3.0, "fault_rel_rms_error": 0.1,
                     "settling_time": 0.5, "ftc_true_ratio": ratio, "input_saturation": [0.0]}],
        "false_alarm_peak": [false_alarm] + [0.0] * (len(faults) - 1),
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


def test_each_verdict_on_its_figure():
    w = {"fault": "fa", "start": 0.0, "stop": 2.0, "fault_rel_rms_error": 0.6, "settling_time": None,
         "ftc_true_ratio": 0.8, "ftc_true_ratio_per_output": [1.2, 0.5],
         "ftc_true_rms_per_output": {"ftc": [0.12, 0.01], "no_ftc": [0.1, 0.02]},
         "crosstalk_peak": [None, 0.3], "missed_detections": 2, "input_saturation": [0.2]}  # fmt: skip
    m = {"paths": 5, "windows": [w], "false_alarm_peak": [0.1, 0.7], "outside_region": 0.02,
         "observer_time_constant": 1.0}  # fmt: skip
    got = {v["verdict"]: v for v in verdicts.verdicts(m, ["u"], ["fa", "fs"], ["y1", "y2"], ["m", "m"])}
    assert set(got) == {"worse than none on an output", "false alarm", "poor estimate", "slow observer",
                        "not settled", "missed", "saturated", "outside region"}  # fmt: skip
    assert "0.12 m with it against 0.1 m without" in got["worse than none on an output"]["text"]
    assert "fs 0.3" in got["worse than none on an output"]["text"]  # the cross-talk that causes it
    assert got["false alarm"]["where"] == "fs" and got["missed"]["value"] == 2
    good = {**w, "fault_rel_rms_error": 0.1, "settling_time": 0.2, "ftc_true_ratio_per_output": [0.5, 0.5],
            "missed_detections": 0, "input_saturation": [0.0]}  # fmt: skip
    ok = {"paths": 5, "windows": [good], "false_alarm_peak": [0.1, 0.2], "outside_region": 0.0,
          "observer_time_constant": 0.1}  # fmt: skip
    assert verdicts.verdicts(ok, ["u"], ["fa", "fs"]) == []


def test_design_warnings_against_the_scenario():
    from fte_casadi.sim import Bias, Scenario

    sc = Scenario(name="s", T=10.0, dt=0.01, faults=(Bias("fa", 1.0, 2.0, 3.0),))
    slow = verdicts.design_warnings({"R_max_real_eig": -1.0}, 0.5, sc)  # 3 x 1 s > the 1 s window
    assert (
        len(slow) == 1 and "slowest time constant is 1" in slow[0] and "shortest fault window (1)" in slow[0]
    )
    assert verdicts.design_warnings({"R_max_real_eig": -10.0}, 0.5, sc) == []  # 3 x 0.1 s fits
    zero = verdicts.design_warnings({"R_max_real_eig": -10.0}, 0.0, sc)
    assert len(zero) == 1 and "lowered to 0" in zero[0]
    assert verdicts.design_warnings({"R_max_real_eig": -1.0}, 0.0, None) == []
