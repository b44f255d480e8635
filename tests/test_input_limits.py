"""Actuator limits (issue #12): the builder, the design document, the step."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from fte_casadi.design import Design
from fte_casadi.errors import DesignFileError, PlantError
from fte_casadi.model import PlantBuilder
from fte_casadi.step import saturate, step_function


def _builder():
    b = PlantBuilder("lim")
    x1, x2 = b.states("x1", "x2")
    u1, u2 = b.inputs("u1", "u2")
    (fa,) = b.faults("fa")
    b.drift([x2 + u1, -x1 - x2 + u2 + fa])
    b.outputs([x1, x2])
    b.reference(u=[0.5, 0.0])
    return b


def test_limits_are_validated_and_stored():
    b = _builder()
    b.input_limits(u1=(0, 1), u2=(None, 2.0))
    lim = b.build().input_limits
    assert np.array_equal(lim, [[0.0, 1.0], [-np.inf, 2.0]])
    assert _builder().build().input_limits is None


@pytest.mark.parametrize("limits, match", [
    ({"u3": (0, 1)}, "'u3' is not an input"),
    ({"u1": (1, 0)}, "needs lower < upper"),
    ({"u1": (0, float("nan"))}, "needs lower < upper"),
    ({"u1": 5}, "must be a pair"),
    ({"u1": (0.6, 1.0)}, "reference input lies outside"),
])  # fmt: skip
def test_bad_limits_are_refused_by_name(limits, match):
    b = _builder()
    b.input_limits(**limits)
    with pytest.raises(PlantError, match=match):
        b.build()


def test_saturate_clips_each_side_and_leaves_open_sides():
    u = ca.SX.sym("u", 3)
    f = ca.Function("f", [u], [saturate(u, np.array([[0, 1], [-np.inf, 2], [-np.inf, np.inf]]))])
    out = np.array(f([-1.0, 5.0, -7.0])).ravel()
    assert np.array_equal(out, [0.0, 2.0, -7.0])
    assert saturate(u, None) is u


def test_document_round_trip_and_step_clips(real_designs, tmp_path):
    d = real_designs["three-tank"]
    d.save(tmp_path / "d.json")
    e = Design.load(tmp_path / "d.json")
    assert np.array_equal(e.input_limits, d.input_limits)
    fn = step_function(e, 0.01)
    z = np.zeros(e.nbar)
    # far below the operating point the controller asks for a large positive flow: clipped to 100
    _, u, *_ = (np.asarray(v).ravel() for v in fn(z, np.array([5.0, 5.0])))
    assert np.all(u == 100.0)
    doc = e.to_dict()
    doc["input_limits"] = [[0.0, None]]  # wrong number of rows
    with pytest.raises(DesignFileError, match="input_limits"):
        Design.from_dict(doc)


def test_three_tank_saturation_from_the_saved_arrays(plants, real_designs, tmp_path):
    """Issue #12: applied pump flows never leave [0, 100] (checked on the saved per-path arrays), the
    metrics' input_saturation lies in [0, 1], and each window's numbers agree with a recomputation
    from the saved arrays."""
    import dataclasses

    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim import load_result, metrics_from_arrays, save_result, simulate

    sc = dataclasses.replace(SCENARIOS["three-tank"]().until(300.0), x0_noise=2.0)  # a start that saturates
    res = simulate(real_designs["three-tank"], plants["three-tank"], sc, paths=4, seed=5, progress=False,
                   record_all=True, record_every=1)  # fmt: skip
    save_result(res, tmp_path / "r.npz")
    back = load_result(tmp_path / "r.npz")
    for run in ("free", "no_ftc", "ftc"):
        u = back.run(run).u
        assert u.min() >= 0.0 and u.max() <= 100.0
    m = back.metrics
    assert len(m["input_saturation"]) == 2 and all(0.0 <= v <= 1.0 for v in m["input_saturation"])
    assert max(m["input_saturation"]) > 0  # the pumps do hit a limit (start-up transient)
    ref = metrics_from_arrays(back)
    assert len(m["windows"]) == len(sc.faults) == 1
    for w, v in zip(m["windows"], ref["windows"]):
        assert w["fault_rel_rms_error"] == pytest.approx(v["fault_rel_rms_error"], rel=1e-12)
        assert w["ftc_true_ratio"] == pytest.approx(v["ftc_true_ratio"], rel=1e-12)
        np.testing.assert_allclose(w["input_saturation"], v["input_saturation"], rtol=1e-12)
    np.testing.assert_allclose(m["input_saturation"], ref["input_saturation"], rtol=1e-12)


def test_manipulator_windows_one_per_fault_window(plants, real_designs):
    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim import simulate

    sc = SCENARIOS["manipulator"]()
    m = simulate(
        real_designs["manipulator"], plants["manipulator"], sc, paths=4, seed=5, progress=False
    ).metrics
    assert [(w["fault"], w["start"], w["stop"]) for w in m["windows"]] == [
        ("fa", 2.5, 5.0),
        ("fs", 7.0, 10.0),
    ]
    assert all(w["fault_rel_rms_error"] is not None and w["ftc_true_ratio"] is not None for w in m["windows"])
    assert m["input_saturation"] == [0.0]  # no limits declared
