"""Metrics document (docs/interface.md) on hand-made arrays, and the .npz round trip."""

import dataclasses

import numpy as np
import pytest

from fte_casadi.errors import SimulationError
from fte_casadi.sim import Bias, RunData, Scenario, SimulationResult, load_result, metrics, save_result
from fte_casadi.sim.metrics import (
    false_alarm_rel_rms,
    fault_rel_rms_error,
    ftc_deviation_ratio,
    state_rms_error,
)


def _hand_made(design, names):
    """2 paths, 1 state, 1 fault, 1 output; t = 0 .. 10 in steps of 0.5 (21 samples)."""
    t = np.arange(21) * 0.5
    P, S = 2, len(t)
    win = (t >= 4.0) & (t < 9.0)  # fault window [4, 9)
    f = np.zeros((P, S, 1))
    f[:, win, 0] = 2.0
    x = np.zeros((P, S, 1))
    x[0, :, 0], x[1, :, 0] = 1.0, -1.0
    xbh = np.zeros((P, S, 3))  # [xhat, fdothat, fhat]
    xbh[0, :, 0], xbh[1, :, 0] = 1.1, -1.3  # errors 0.1 and 0.3 everywhere
    xbh[:, :, 2] = f[:, :, 0] + 0.5 * win  # fhat = f + 0.5 in the window
    xbh[:, (t >= 1.0) & (t < 2.5), 2] = 0.4  # and a false alarm of 0.4 at t = 1, 1.5, 2
    y_free = np.zeros((P, S, 1))
    y_nf = y_free + 2.0 * win[None, :, None]
    yc = y_free + 0.5 * win[None, :, None]

    def run(y, yc_):
        return RunData(x=x, xbarhat=xbh, f=f, u=np.zeros((P, S, 1)), y=y, yc=yc_)

    sc = Scenario(name="hand", T=10.0, dt=0.5, faults=(Bias("fa", 2.0, 4.0, 9.0),))
    return SimulationResult(
        plant="hand",
        t=t,
        dt=0.5,
        T=10.0,
        seed=3,
        paths=P,
        record_every=1,
        free=run(y_free, y_free),
        no_ftc=run(y_nf, y_nf),
        ftc=run(y_nf, yc),
        scenario=sc,
        design=design,
        names=names,
        wall_s=1.5,
        compiled=True,
    )


NAMES = {
    "states": ["x1"],
    "state_units": ["m"],
    "inputs": ["u"],
    "outputs": ["y1"],
    "output_units": ["m"],
    "faults": ["fa"],
    "fault_kinds": ["actuator"],
    "time_unit": "s",
}


def test_metrics_hand_made(lqr_designs):
    res = _hand_made(lqr_designs["manipulator"], NAMES)
    m = metrics(res)
    assert set(m) == {
        "paths",
        "dt",
        "T",
        "seed",
        "state_rms_error",
        "fault_rel_rms_error",
        "false_alarm_rel_rms",
        "ftc_deviation_ratio",
        "windows",
        "input_saturation",
        "wall_s",
    }
    assert (m["paths"], m["dt"], m["T"], m["seed"], m["wall_s"]) == (2, 0.5, 10.0, 3, 1.5)
    # one window per fault profile, with the same numbers as the pooled ones here (one window)
    (w,) = m["windows"]
    assert (w["fault"], w["start"], w["stop"]) == ("fa", 4.0, 9.0)
    assert w["fault_rel_rms_error"] == pytest.approx(0.25, abs=1e-12)
    assert w["ftc_deviation_ratio"] == pytest.approx(0.25, abs=1e-12)
    assert m["input_saturation"] == [0.0] and w["input_saturation"] == [0.0]  # the fixture has no limits
    # state error: RMS 0.1 on path 0, 0.3 on path 1 -> mean 0.2
    assert m["state_rms_error"] == pytest.approx([0.2], abs=1e-12)
    # fault: window [4, 9) minus its first 20 % -> [5, 9): fhat - f = 0.5, f = 2 -> 0.25
    assert m["fault_rel_rms_error"] == pytest.approx([0.25], abs=1e-12)
    # false alarm: t >= 1 outside [4, 9) is 9 samples (1 .. 3.5 and 9 .. 10), fhat = 0.4 on 3 of them:
    # RMS 0.4 / sqrt(3), against RMS(f) = 2 over [5, 9)
    assert m["false_alarm_rel_rms"] == pytest.approx([0.4 / np.sqrt(3) / 2], abs=1e-12)
    # outputs: yc - y_free = 0.5, y_noFTC - y_free = 2 over the window -> 0.25
    assert m["ftc_deviation_ratio"] == pytest.approx(0.25, abs=1e-12)


def test_metric_functions_edge_cases():
    t = np.linspace(0, 2, 5)  # 0, .5, 1, 1.5, 2
    x = np.zeros((1, 5, 2))
    xh = np.zeros((1, 5, 2))
    xh[0, :, 1] = [9, 9, 1, 1, 1]  # start-up transient before t = 1 is ignored
    assert state_rms_error(x, xh, t) == pytest.approx([0.0, 1.0])
    f = np.zeros((1, 5, 1))
    assert fault_rel_rms_error(f, f, t, [[(0.0, 2.0)]]) == [None]  # no fault: undefined
    assert fault_rel_rms_error(f, f, t, [[]]) == [None]
    assert false_alarm_rel_rms(f, f, t, [[(0.0, 2.0)]]) == [None]  # no fault: undefined
    f[0, 2:4, 0] = 1.0
    assert false_alarm_rel_rms(f, f, t, [[(0.0, 2.5)]]) == [None]  # no sample outside the window
    y = np.zeros((1, 5, 1))
    assert ftc_deviation_ratio(y, y, y, t, [[(0.0, 1.0)]]) is None


def test_npz_round_trip(tmp_path, lqr_designs):
    res = _hand_made(lqr_designs["manipulator"], NAMES)
    path = save_result(res, tmp_path / "r.npz")
    back = load_result(path)
    for f in dataclasses.fields(SimulationResult):
        a, b = getattr(res, f.name), getattr(back, f.name)
        if isinstance(a, RunData):
            for g in dataclasses.fields(RunData):
                np.testing.assert_array_equal(getattr(a, g.name), getattr(b, g.name))
        elif isinstance(a, np.ndarray):
            np.testing.assert_array_equal(a, b)
        elif f.name == "design":
            assert b.to_dict() == a.to_dict()
        else:
            assert a == b, f.name
    assert metrics(back) == metrics(res)


def test_load_errors(tmp_path):
    with pytest.raises(SimulationError, match="does not exist"):
        load_result(tmp_path / "missing.npz")
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a zip")
    with pytest.raises(SimulationError, match="not a readable"):
        load_result(bad)
    other = tmp_path / "other.npz"
    np.savez(other, a=np.zeros(2))
    with pytest.raises(SimulationError, match="not an fte simulation result"):
        load_result(other)
