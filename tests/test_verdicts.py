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
    ftc_ok, measured_ok, fa_ok = search._admissible(m)
    explained = limits.explain_metrics(d, m)
    bad = side > 0
    assert sum("worse than none" in w for w in warned) == int(bad) and ftc_ok == measured_ok == (not bad)
    assert sum("false alarms" in w for w in warned) == int(bad) and fa_ok == (not bad)
    assert len(explained) == 2 * int(bad)  # one window, one fault explained above the thresholds, none below
    # one output at the threshold, the window as a whole well below it: warned and judged alike (#38)
    m["windows"][0] |= {"ftc_true_ratio": 0.5, "ftc_true_ratio_per_output": [0.3, ratio]}
    warned = _warnings(m, list(d.names["inputs"]), faults)
    assert sum("makes the true output" in w and "worse than none" in w for w in warned) == int(bad)
    assert search._admissible(m)[:2] == (not bad, not bad)


def test_each_verdict_on_its_figure():
    w = {"fault": "fa", "start": 0.0, "stop": 2.0, "fault_rel_rms_error": 0.6, "settling_time": None,
         "ftc_true_ratio": 0.8, "ftc_true_ratio_per_output": [1.2, 0.5],
         "ftc_true_rms_per_output": {"ftc": [0.12, 0.01], "no_ftc": [0.1, 0.02]},
         "crosstalk_peak": [None, 0.3], "missed_detections": 2, "input_saturation": [0.2]}  # fmt: skip
    m = {"paths": 5, "windows": [w], "false_alarm_peak": [0.1, 0.7], "outside_region": 0.02,
         "observer_time_constant": 1.0, "c_accepted_range": {"lo": [-1.0, -2.0], "hi": [1.0, 2.0]},
         "outside_c_range": 0.003, "outside_c_range_per_output": [0.0, 0.003], "outside_c_range_paths": 0.4,
         "outside_c_range_first": 1.25}  # fmt: skip
    got = {v["verdict"]: v for v in verdicts.verdicts(m, ["u"], ["fa", "fs"], ["y1", "y2"], ["m", "m"])}
    assert set(got) == {"worse than none on an output", "false alarm", "poor estimate", "slow observer",
                        "not settled", "missed", "saturated", "outside region", "C stops"}  # fmt: skip
    assert "on 40 % of the paths" in got["C stops"]["text"] and "y2 outside [-2, 2] on 0.3 % of the samples, " \
        "first at t = 1.25" in got["C stops"]["text"]  # fmt: skip
    assert not any(v["verdict"] == "C stops" for v in verdicts.verdicts({**m, "outside_c_range_paths": 0.0}))
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


def test_a_ratio_above_one_is_worse_than_none_only_when_its_interval_is():
    """The three-tank's h1 of 1.003-1.012 over seeds is a tie: a ratio above 1 whose interval over the paths
    holds 1 gets no verdict; with the interval above 1 it is worse than none (window and output alike)."""

    def doc(r, iv, per, per_iv):
        w = {"fault": "fa", "start": 0.0, "stop": 2.0, "fault_rel_rms_error": 0.1, "settling_time": 0.2,
             "ftc_true_ratio": r, "ftc_true_ratio_interval": iv, "ftc_true_ratio_per_output": per,
             "ftc_true_ratio_per_output_interval": per_iv, "input_saturation": [0.0]}  # fmt: skip
        return {"paths": 20, "windows": [w], "false_alarm_peak": [0.1]}

    def said(m):
        return sorted(v["verdict"] for v in verdicts.verdicts(m, ["u"], ["fa"], ["h1", "h2"]))

    tie = doc(0.2, [0.19, 0.21], [1.008, 0.19], [[0.997, 1.02], [0.18, 0.2]])
    assert said(tie) == []
    worse = doc(0.2, [0.19, 0.21], [1.008, 0.19], [[1.002, 1.014], [0.18, 0.2]])
    (v,) = verdicts.verdicts(worse, ["u"], ["fa"], ["h1", "h2"])
    assert v["verdict"] == "worse than none on an output" and "95 % interval 1.002-1.014" in v["text"]
    assert said(doc(1.05, [0.98, 1.1], [1.05, 1.05], [[0.9, 1.2], [0.9, 1.2]])) == []
    assert said(doc(1.05, [1.01, 1.1], [1.05, 1.05], [[0.9, 1.2], [0.9, 1.2]])) == ["worse than none"]


def test_tolerant_control_after_a_window_is_judged_like_the_window():
    """After a window (``after_window``: no fault in the plant) a ratio whose interval lies above 1 is worse than
    none, on the whole or on one output, and the verdict names what tolerant control still applied there and how
    long the estimate took to fall back; an interval that holds 1 is a tie; no span, no verdict."""

    def doc(r, iv, per, per_iv, comp):
        a = {"start": 2.0, "stop": 5.0, "ftc_true_ratio": r, "ftc_true_ratio_interval": iv,
             "ftc_true_ratio_per_output": per, "ftc_true_ratio_per_output_interval": per_iv,
             "ftc_compensation_rms": comp}  # fmt: skip
        w = {"fault": "fa", "start": 0.0, "stop": 2.0, "fault_rel_rms_error": 0.1, "settling_time": 0.2,
             "release_time": 0.7, "ftc_true_ratio": 0.2, "ftc_true_ratio_interval": [0.19, 0.21],
             "ftc_true_ratio_per_output": [0.2, 0.2], "ftc_true_ratio_per_output_interval": [[0.19, 0.21]] * 2,
             "input_saturation": [0.0], "after_window": a}  # fmt: skip
        return {"paths": 20, "windows": [w], "false_alarm_peak": [0.1]}

    def said(m):
        return [
            (v["verdict"], v["where"], v["text"]) for v in verdicts.verdicts(m, ["u"], ["fa"], ["h1", "h2"])
        ]

    ((v, where, text),) = said(doc(1.43, [1.42, 1.44], [1.45, 1.15], [[1.44, 1.46], [1.14, 1.16]], [0.39]))
    assert v == "worse than none after a window" and where == "the span after the window of fa [0, 2), [2, 5)"
    assert (
        "ratio 1.43 > 1" in text
        and "h1: 1.45" in text
        and "RMS 0.39 per input" in text
        and "0.7 after its end" in text
    )
    ((v, where, text),) = said(doc(0.9, [0.8, 0.95], [1.08, 0.5], [[1.02, 1.1], [0.4, 0.6]], [0.0]))
    assert v == "worse than none after a window on an output" and where.endswith(", h1")
    assert "applied nothing there" in text
    assert said(doc(1.05, [0.98, 1.1], [1.05, 1.05], [[0.9, 1.2], [0.9, 1.2]], [0.1])) == []
    # the net of the fault's episode, the window and the span together, where measured
    net = doc(1.43, [1.42, 1.44], [1.45, 1.15], [[1.44, 1.46], [1.14, 1.16]], [0.39])
    net["windows"][0]["after_window"].update(
        ftc_true_ratio_with_window=0.75, ftc_true_ratio_with_window_interval=[0.74, 0.76]
    )
    ((_, _, text),) = said(net)
    assert "together it is better than none (ftc_true_ratio_with_window 0.75, 95 % interval 0.74-0.76" in text
    # a result saved before the compensation was recorded: the verdict, without a cause it cannot know
    ((v, _, text),) = said(doc(1.43, [1.42, 1.44], [1.45, 1.15], [[1.44, 1.46], [1.14, 1.16]], None))
    assert (
        v == "worse than none after a window" and "still adds" not in text and "applied nothing" not in text
    )
    none = doc(1.4, [1.3, 1.5], [1.4, 1.4], [[1.3, 1.5]] * 2, [0.1])
    none["windows"][0]["after_window"] = None
    assert said(none) == []


def test_false_alarm_rates_are_judged_against_the_promise():
    """On the fault-free paths and in the faulty run outside a fault's windows: a verdict when the measured
    rate's interval lies above the interval the calibration promised; a rate inside it, or an interval that
    reaches into it, is none."""
    e = {"fault": "fs", "false_alarm_rate_asked": 1 / 3600, "false_alarm_rate_interval": [1.5e-4, 4.5e-4],
         "false_alarm_rate": 3e-4, "false_alarm_rate_measured_interval": [1e-4, 6e-4],
         "false_alarm_rate_ftc_run": 0.76, "false_alarm_rate_ftc_run_interval": [0.61, 0.94]}  # fmt: skip
    m = {"paths": 20, "windows": [], "detection": [e]}
    (v,) = verdicts.verdicts(m, [], ["fs"])
    assert v["verdict"] == "false-alarm rate" and "in the faulty run" in v["text"] and v["value"] == 0.76
    m["detection"][0] = {**e, "false_alarm_rate_ftc_run_interval": [4e-4, 0.94]}  # reaches into the promise
    assert verdicts.verdicts(m, [], ["fs"]) == []
    m["detection"][0] = {**e, "false_alarm_rate": 2e-3, "false_alarm_rate_measured_interval": [1e-3, 3e-3],
                         "false_alarm_rate_ftc_run": None}  # fmt: skip
    (v,) = verdicts.verdicts(m, [], ["fs"])
    assert "on fault-free paths" in v["text"]


def test_a_standing_alarm_is_said_and_is_no_detection():
    w = {"fault": "fs", "start": 7.0, "stop": 10.0, "fault_rel_rms_error": 0.1, "settling_time": 0.2,
         "ftc_true_ratio": 0.7, "missed_detections": 0, "standing_alarm_paths": 7, "input_saturation": [0.0]}  # fmt: skip
    (v,) = verdicts.verdicts({"paths": 20, "windows": [w]}, ["u"], ["fa", "fs"])
    assert v["verdict"] == "standing alarm" and v["value"] == 7 and "7 of 20 paths" in v["text"]


def test_a_poor_estimate_needs_its_interval_at_or_above_the_limit():
    w = {"fault": "fa", "start": 0.0, "stop": 2.0, "fault_rel_rms_error": 0.52, "settling_time": 0.2,
         "ftc_true_ratio": 0.5, "input_saturation": [0.0]}  # fmt: skip
    poor = {**w, "fault_rel_rms_error_interval": [0.505, 0.54]}
    tie = {**w, "fault_rel_rms_error_interval": [0.47, 0.57]}
    assert [v["verdict"] for v in verdicts.verdicts({"paths": 9, "windows": [poor]})] == ["poor estimate"]
    assert verdicts.verdicts({"paths": 9, "windows": [tie]}) == []


def test_a_plant_without_unknown_inputs_is_not_told_about_them():
    """The rank test of a fault's column is "separation from the unknown inputs" only where the plant has some;
    without, it says how well the outputs see the fault at all, and the message says that."""
    from fte_casadi.design._limits import FaultLimits, causes

    weak = dict(fault="fa", rightmost_zero=(None,), separation_inputs=(0.01,), separation_faults=(float("inf"),),
                slowest_mode=-5.0)  # fmt: skip
    with_d, seen_d = causes(FaultLimits(**weak), 2.0)
    without, seen = causes(FaultLimits(**weak, has_unknown_inputs=False), 2.0)
    assert (
        any("from the unknown inputs only weakly" in f for f in with_d)
        and "from the unknown inputs" in seen_d
    )
    assert not any("unknown inputs only weakly" in f for f in without) and "unknown inputs 0.01" not in seen
    assert any("see fa only weakly (the plant has no unknown inputs)" in f and "0.01" in f for f in without)


def test_a_saturated_input_is_explained_by_the_noise_through_the_gain_when_it_is():
    """A window whose input sits at its limits is explained by the measurement noise where the loop's direct path
    K H alone moves the input by a third of its half-range (the quadruple tank's committed design: pumps of
    half-range 5 V); a noise that does not reach that, or a run without noise, explains nothing."""
    import pathlib

    import numpy as np

    from fte_casadi.design import Design
    from fte_casadi.design._limits import NOISE_SATURATES, noise_saturates

    d = Design.load(
        pathlib.Path(__file__).resolve().parents[1] / "generated" / "quadruple_tank" / "design.json"
    )
    n = int(d.dims.n)
    gain = np.asarray(d.K[0]) @ np.asarray(d.H)[:n]  # the direct path from each output to each input
    w = {"input_saturation": [0.9, 0.0]}
    noise = (
        2.0 * NOISE_SATURATES * 5.0 / max(np.abs(gain[0]).max(), 1e-300)
    )  # twice what it takes on one output
    k = int(np.argmax(np.abs(gain[0])))
    big = [noise if q == k else 0.0 for q in range(int(d.dims.p))]
    text = noise_saturates(d, {"measurement_noise": big}, w)
    assert text.startswith("input dv1 is at a limit 90 % of the window") and "half-range 5" in text
    assert "dv2" not in text  # not saturated in this window
    assert (
        noise_saturates(d, {"measurement_noise": [v / 4 for v in big]}, w) == ""
    )  # too small to reach the limit
    assert noise_saturates(d, {"measurement_noise": None}, w) == ""


@pytest.mark.parametrize("applied", [0.0, 0.02])
def test_a_window_tolerant_control_left_alone_is_blamed_on_what_it_carried_in(applied):
    """A window worse than none where the compensation applied is zero at every sample (the gate kept every
    estimate out of u): the verdict names the carry-over with the runs' deviations at the onset, not the
    other faults' cross-talk, which did not reach the plant; where compensation was applied, the cross-talk."""
    w = {"fault": "fs", "start": 8.0, "stop": 11.0, "ftc_true_ratio": 1.0016, "ftc_true_ratio_interval": [1.001, 1.002],
         "ftc_compensation_rms": [applied], "onset_deviation": {"ftc": 1.16e-5, "no_ftc": 3.32e-5},
         "crosstalk_peak": [0.52, None], "input_saturation": [0.0]}  # fmt: skip
    (v,) = [
        v
        for v in verdicts.verdicts({"windows": [w]}, faults=["fa", "fs"])
        if v["verdict"] == "worse than none"
    ]
    carried = "applied nothing" in v["text"]
    assert carried == (applied == 0.0)
    assert ("1.16e-05" in v["text"] and "3.32e-05" in v["text"]) == carried
    assert ("cross-talk" in v["text"]) == (not carried)


def test_a_ratio_just_above_1_is_printed_above_1():
    """A window worse than none by 1.2e-7 (the levitation's sensor window: the runs' paths are shared, so the
    interval is that narrow) says by how much, never "ftc_true_ratio 1 > 1"."""
    w = {"fault": "fs", "start": 1.75, "stop": 2.25, "ftc_true_ratio": 1.0000001164,
         "ftc_true_ratio_interval": [1.0000000701, 1.000000159], "ftc_true_ratio_per_output": [1.0000001, 0.99997]}  # fmt: skip
    (v,) = [v for v in verdicts.verdicts({"windows": [w]}, ["u"], ["fa", "fs"], ["y1", "y2"])
            if v["verdict"] == "worse than none"]  # fmt: skip
    assert "ftc_true_ratio 1.00000012 > 1, 95 % interval 1.00000007-1.00000016" in v["text"], v["text"]
    assert "y1: 1.0000001, y2: 0.99997" in v["text"]


def test_a_sensor_fault_that_moves_the_plant_more_than_it_misreads_it_is_said():
    """The levitation's gap-sensor window (`tests/plant_levitation.py:maglev_near`, 8 paths, seed 1): a 0.2 mm bias
    moves the true gap by 0.536 mm RMS over the window, with tolerant control and without. The verdict compares each
    true output's RMS deviation from the fault-free run with the fault as that output reads it
    (``sensor_fault_peak_per_output``), above :data:`SENSOR_MOTION` times it, per output; nothing for an actuator fault
    (zeros there) or a motion at the fault's size."""
    w = {"fault": "fs", "start": 1.75, "stop": 2.25, "sensor_fault_peak_per_output": [0.2, 0.0],
         "ftc_true_rms_per_output": {"ftc": [0.5355, 0.1412], "no_ftc": [0.5354, 0.1412]}}  # fmt: skip
    got = [v for v in verdicts.verdicts({"windows": [w]}, [], ["fa", "fs"], ["gap_dev", "i_dev"], ["mm", "A"])
           if v["verdict"] == "sensor fault moves the plant"]  # fmt: skip
    assert len(got) == 1 and got[0]["where"] == "the window of fs [1.75, 2.25), gap_dev"
    assert abs(got[0]["value"] - 0.5355 / 0.2) < 1e-12
    assert (
        "a fault of 0.2 mm on the reading of gap_dev moves the TRUE gap_dev by 0.535 mm RMS" in got[0]["text"]
    )
    assert "0.535 mm without" in got[0]["text"]
    at = {
        **w,
        "ftc_true_rms_per_output": {"ftc": [0.2, 0.1], "no_ftc": [0.3, 0.1]},
    }  # at the fault's size: not above
    actuator = {**w, "sensor_fault_peak_per_output": [0.0, 0.0]}
    for quiet in (at, actuator):
        assert not any(
            v["verdict"] == "sensor fault moves the plant" for v in verdicts.verdicts({"windows": [quiet]})
        )
    # another fault's window overlapping it: the motion is that fault's too, and nothing is said; one that only
    # touches it (ends at its start), or another window of the same fault, does not count
    for other, said in ((("fa", 2.0, 3.0), False), (("fa", 1.0, 1.75), True), (("fs", 2.0, 2.5), True)):
        v = {"fault": other[0], "start": other[1], "stop": other[2]}
        got = verdicts.verdicts({"windows": [w, v]}, [], ["fa", "fs"], ["gap_dev", "i_dev"])
        assert any(g["verdict"] == "sensor fault moves the plant" for g in got) == said, other


def test_a_fault_entering_a_state_equation_is_not_read_as_a_sensor_fault():
    """``sensor_gains``: |Df| per output and fault, its column zeroed for a fault that also enters a state equation
    (a column of Bf or Gf nonzero in some rule): the verdict's "the fault enters only the measurement" holds."""
    from types import SimpleNamespace

    import numpy as np

    from fte_casadi.sim._reduce import sensor_gains

    z = np.zeros((2, 3))
    rules = [SimpleNamespace(Bf=z.copy(), Gf=z.copy()) for _ in range(2)]
    rules[1].Bf[0, 1] = 0.5  # fault 1 enters the drift in rule 1
    rules[0].Gf[1, 2] = 0.1  # fault 2 the diffusion in rule 0
    Df = np.array([[-2.0, 1.0, 0.0], [0.0, 3.0, 4.0]])
    got = sensor_gains(SimpleNamespace(Df=Df, local_models=rules))
    assert got == [[2.0, 0.0, 0.0], [0.0, 0.0, 0.0]]


def test_the_region_left_is_said_with_where_the_states_went():
    """``outside region`` names each state the runs took beyond the region, with its extremes (``state_range``)
    against the region (an open side reads inf), and no state kept within it: the levitation's 3.1 % hid a gap
    1.89 mm off against a region of 1 mm."""
    m = {"outside_region": 0.031, "windows": [],
         "state_range": {"lo": [-1.892, -20.0, -0.5572], "hi": [1.053, 30.0, 0.356]},
         "region": {"lo": [-1.0, -50.0, None], "hi": [1.0, 50.0, 0.3]}}  # fmt: skip
    (v,) = verdicts.verdicts(m, states=["e", "v", "j"], state_units=["mm", "mm/s", "A"])
    assert v["verdict"] == "outside region"
    assert v["text"].endswith(": the runs take e -1.892 to 1.053 mm (region -1 to 1), j -0.5572 to 0.356 A "
                              "(region -inf to 0.3)")  # fmt: skip
    (old,) = verdicts.verdicts({k: m[k] for k in ("outside_region", "windows")})  # a document without them
    assert old["text"].endswith("is not exact")
    # an excursion that 4 digits would print as its bound is printed with more
    near = {**m, "state_range": {"lo": [-0.5, -20.0, -0.2], "hi": [1.00004, 30.0, 0.2]}}
    (v,) = verdicts.verdicts(near, states=["e", "v", "j"])
    assert v["text"].endswith(": the runs take e -0.5 to 1.00004 (region -1 to 1)")
    # fte simulate's warnings pass the plant's state names and units on
    said = _warnings(m, [], states=["e", "v", "j"], state_units=["mm", "mm/s", "A"])
    assert said == [
        "warning: " + verdicts.verdicts(m, states=["e", "v", "j"], state_units=["mm", "mm/s", "A"])[0]["text"]
    ]


def test_an_open_side_of_the_region_is_null_in_the_document():
    """The builder leaves an open side NaN (an infinite one is open too): the metrics document's ``region`` holds
    null there, so that it stays JSON, and the verdict reads it as open."""
    from fte_casadi.sim._reduce import region_doc

    nan, inf = float("nan"), float("inf")
    assert region_doc(([-1.0, nan, -inf], [1.0, 2.0, nan])) == {
        "lo": [-1.0, None, None],
        "hi": [1.0, 2.0, None],
    }
    assert region_doc(None) is None
