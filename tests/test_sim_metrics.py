"""Metrics document (docs/interface.md) on hand-made arrays, and the .npz round trip."""

import dataclasses

import numpy as np
import pytest

from fte_casadi.errors import SimulationError
from fte_casadi.sim import Bias, RunData, Scenario, SimulationResult, load_result, metrics, save_result


def _hand_made(design, names):
    """2 paths, 1 state, 1 fault, 1 output; t = 0 .. 10 in steps of 0.5 (21 samples); the observer's slowest
    time constant 1/3, so the start-up allowance and the one after a window are 3 x 1/3 = 1."""
    design = dataclasses.replace(design, C=np.array([[1.0]]),
                                 checks={**design.checks, "R_max_real_eig": -3.0})  # fmt: skip
    t = np.arange(21) * 0.5
    P, S = 2, len(t)
    win = (t >= 4.0) & (t < 9.0)  # fault window [4, 9): 10 samples
    f = np.zeros((P, S, 1))
    f[:, win, 0] = 2.0
    x = np.zeros((P, S, 1))
    x[0, :, 0], x[1, :, 0] = 1.0, -1.0
    xbh = np.zeros((P, S, 3))  # [xhat, fdothat, fhat]
    xbh[0, :, 0], xbh[1, :, 0] = 1.1, -1.3  # errors 0.1 and 0.3 everywhere
    xbh[:, :, 2] = f[:, :, 0] + 0.1 * win  # fhat = f + 0.1 in the window ...
    xbh[:, (t >= 4.0) & (t < 5.0), 2] += 0.4  # ... + 0.5 in its first second (4, 4.5)
    xbh[:, (t >= 1.0) & (t < 2.5), 2] = 0.4  # and a false alarm of 0.4 at t = 1, 1.5, 2
    y_free = np.zeros((P, S, 1))
    y_nf = y_free + 2.0 * win[None, :, None]
    yc = y_free + 0.5 * win[None, :, None]

    def run(xr, y, yc_):
        return RunData(x=xr, xbarhat=xbh, f=f, u=np.zeros((P, S, 1)), y=y, yc=yc_)

    sc = Scenario(name="hand", T=10.0, dt=0.5, faults=(Bias("fa", 2.0, 4.0, 9.0),))
    return SimulationResult(
        plant="hand",
        t=t,
        dt=0.5,
        T=10.0,
        seed=3,
        paths=P,
        record_every=1,
        free=run(x - 0.5 * win[None, :, None], y_free, y_free),  # C x_FTC - C x_free = 0.5 in the window
        no_ftc=run(x + 1.5 * win[None, :, None], y_nf, y_nf),  # C x_noFTC - C x_free = 2
        ftc=run(x, y_nf, yc),
        scenario=sc,
        design=design,
        names=names,
        wall_s=1.5,
        compiled=True,
        region=(np.array([-1.2]), np.array([1.2])),  # the no-FTC run leaves it at 2.5 in the window
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
    assert {"transient", "settle_after", "fault_rel_rms_error_settled", "false_alarm_peak", "ftc_true_ratio",
            "ftc_compensated_ratio", "detection", "outside_region"} <= set(m)  # fmt: skip
    assert "ftc_deviation_ratio" not in m
    assert (m["paths"], m["dt"], m["T"], m["seed"], m["wall_s"]) == (2, 0.5, 10.0, 3, 1.5)
    assert (m["transient"], m["settle_after"]) == (pytest.approx(1.0), pytest.approx(1.0))
    (w,) = m["windows"]
    assert (w["fault"], w["start"], w["stop"]) == ("fa", 4.0, 9.0)
    whole = np.sqrt((2 * 0.5**2 + 8 * 0.1**2) / 10) / 2  # the WHOLE window, start-up included
    assert w["fault_rel_rms_error"] == pytest.approx(whole, abs=1e-12)
    assert m["fault_rel_rms_error"] == pytest.approx([whole], abs=1e-12)
    # the settled part [5, 9): error 0.1 against 2
    assert w["fault_rel_rms_error_settled"] == pytest.approx(0.05, abs=1e-12)
    assert m["fault_rel_rms_error_settled"] == pytest.approx([0.05], abs=1e-12)
    assert w["settling_time"] == pytest.approx(1.0)  # the error 0.5 > 10 % of 2 at 4, 4.5; 0.1 from 5 on
    assert w["release_time"] == pytest.approx(0.0)  # the estimate is 0 from t = 9 on
    assert m["input_saturation"] == [0.0] and w["input_saturation"] == [0.0]  # the fixture has no limits
    # state error after the transient (t >= 1): RMS 0.1 on path 0, 0.3 on path 1 -> mean 0.2
    assert m["state_rms_error"] == pytest.approx([0.2], abs=1e-12)
    # outside the fault: t >= 1, outside [4, 9) and not within 1 of its end: 1 .. 3.5 and 10 (7 samples);
    # fhat = 0.4 on 3 of them: peak 0.4 against the fault's 2, RMS 0.4 sqrt(3 / 7) against 2
    assert m["false_alarm_peak"] == pytest.approx([0.2], abs=1e-12)
    assert m["false_alarm_rel_rms"] == pytest.approx([0.4 * np.sqrt(3 / 7) / 2], abs=1e-12)
    # the true outputs: C x_FTC - C x_free = 0.5, C x_noFTC - C x_free = 2 over the window -> 0.25
    assert m["ftc_true_ratio"] == pytest.approx(0.25, abs=1e-12)
    assert w["ftc_true_ratio"] == pytest.approx(0.25, abs=1e-12)
    assert w["ftc_true_ratio_per_output"] == pytest.approx([0.25], abs=1e-12)
    # the compensated reading: yc - y_free = 0.5, y_noFTC - y_free = 2 -> 0.25
    assert m["ftc_compensated_ratio"] == pytest.approx(0.25, abs=1e-12)
    # the no-FTC run at 2.5 (> 1.2) on the window's 10 of 21 samples, on both paths
    assert m["outside_region"] == pytest.approx(10 / 21, abs=1e-12)


def test_a_fault_of_size_zero_gets_no_ratio(lqr_designs):
    res = _hand_made(lqr_designs["manipulator"], NAMES)
    zero = dataclasses.replace(res.ftc, f=np.zeros_like(res.ftc.f))
    m = metrics(dataclasses.replace(res, ftc=zero, no_ftc=dataclasses.replace(res.no_ftc, f=zero.f)))
    (w,) = m["windows"]
    assert m["fault_rel_rms_error"] == [None] and w["fault_rel_rms_error"] is None
    assert w["ftc_true_ratio"] is None and w["ftc_compensated_ratio"] is None and m["ftc_true_ratio"] is None
    assert m["false_alarm_peak"] == [None]


def test_npz_round_trip(tmp_path, lqr_designs):
    res = _hand_made(lqr_designs["manipulator"], NAMES)
    # the saved design must be a whole document (the hand-made one has a 1 x 1 C): the real one, the metrics kept
    res = dataclasses.replace(res, design=lqr_designs["manipulator"], metrics=metrics(res))
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
