"""The plant builder: validation once, with messages naming argument and shapes."""

import casadi as ca
import numpy as np
import pytest

from fte_casadi import PlantBuilder
from fte_casadi.errors import PlantError


def _pendulum(**over):
    b = PlantBuilder("p")
    th, om = b.states("theta", "omega")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa")
    mu = b.premise("mu", ca.if_else(ca.fabs(th) < 1e-4, 1 - th**2 / 6, ca.sin(th) / th))
    syms = (th, om, u, d, fa, mu)
    b.drift(over["drift"](*syms) if "drift" in over else [om + 0.1 * d, -9.8 * mu * th - 0.5 * om + u + fa])
    b.diffusion([0.0, 0.01 * om])
    b.outputs(over["outputs"](*syms) if "outputs" in over else [th, om])
    if "region" in over:
        b.region(**over["region"])
    else:
        b.region(theta=(-3.0, 3.0))
    b.reference(u=[0.0])
    b.initial_state(over.get("x0", [0.1, 0.0]))
    return b


def test_build_gives_frozen_plant_with_C_and_Df():
    b = _pendulum()
    p = b.build()
    assert (p.n, p.m, p.p, p.ld, p.lf) == (2, 1, 2, 1, 1)
    np.testing.assert_array_equal(p.C, np.eye(2))
    np.testing.assert_array_equal(p.Df, np.zeros((2, 1)))
    with pytest.raises(AttributeError):
        p.name = "other"  # frozen


def test_sensor_fault_gives_Df():
    b = PlantBuilder("s")
    (x,) = b.states("x")
    (u,) = b.inputs("u")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([-x + u])
    b.outputs([2 * x + 3 * fs])
    p = b.build()
    assert p.C[0, 0] == 2 and p.Df[0, 0] == 3


def test_wrong_drift_length_names_expected_and_actual():
    b = _pendulum(drift=lambda th, om, u, d, fa, mu: [om])
    with pytest.raises(PlantError, match="drift has the wrong number of rows; expected 2 instead of 1"):
        b.build()


def test_nonlinear_output_refused():
    b = _pendulum(outputs=lambda th, om, *_: [om, ca.sin(th)])
    with pytest.raises(PlantError, match=r"linear.*nonlinear: output 2 \(y2 = sin\(theta\)\)") as e:
        b.build()
    assert "output 1" not in str(e.value)


def test_uncovered_nonlinearity_names_the_term():
    b = _pendulum(drift=lambda th, om, u, d, fa, mu: [om, -9.8 * ca.cos(th) * th + u + fa])
    with pytest.raises(PlantError, match="nonlinear in 'theta'.*not covered by any premise"):
        b.build()


def test_fault_entering_nonaffinely_refused():
    b = _pendulum(drift=lambda th, om, u, d, fa, mu: [om, -9.8 * mu * th + u + fa**2])
    with pytest.raises(PlantError, match="nonlinear in 'fa'"):
        b.build()


def test_unknown_input_times_state_refused():
    b = _pendulum(drift=lambda th, om, u, d, fa, mu: [om + d * om, -9.8 * mu * th + u + fa])
    with pytest.raises(PlantError, match="nonlinear"):
        b.build()


@pytest.mark.parametrize(
    "region, match",
    [
        ({"theta": (3.0, -3.0)}, "lower bound of 'theta' must be below"),
        ({"theta": (-np.inf, 3.0)}, "must be finite"),
        ({"thetaa": (-1.0, 1.0)}, "not a state"),
        ({"theta": "wide"}, "must be a pair"),
    ],
)
def test_region_checks(region, match):
    b = _pendulum(region=region)
    with pytest.raises(PlantError, match=match):
        b.build()


def test_unbounded_premise_refused():
    b = PlantBuilder("p")
    th, om = b.states("theta", "omega")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    mu = b.premise("mu", ca.sin(th))
    b.drift([om, mu + u + fa])
    b.outputs([th, om])
    with pytest.raises(PlantError, match="depends on state 'theta', which has no bounds"):
        b.build()


def test_undeclared_symbol_refused():
    b = _pendulum(drift=lambda th, om, u, d, fa, mu: [om, ca.SX.sym("k") * th + u + fa])
    with pytest.raises(PlantError, match=r"symbol\(s\) \['k'\]"):
        b.build()


def test_bad_x0_and_names():
    b = _pendulum(x0=[0.1])
    with pytest.raises(PlantError, match="initial state must hold 2"):
        b.build()
    b2 = PlantBuilder("q")
    with pytest.raises(PlantError, match="not a valid identifier"):
        b2.states("x 1")
    b2.states("x")
    with pytest.raises(PlantError, match="already used"):
        b2.inputs("x")
    with pytest.raises(PlantError, match="fault kind"):
        b2.faults("f", kind="sideways")


def test_no_faults_refused():
    b = PlantBuilder("p")
    (x,) = b.states("x")
    b.inputs("u")
    b.drift([-x])
    b.outputs([x])
    with pytest.raises(PlantError, match="no faults"):
        b.build()


def test_design_defaults_validated():
    b = PlantBuilder("p")
    with pytest.raises(PlantError, match="unknown parameter"):
        b.design_defaults(gama=1.0)
    with pytest.raises(PlantError, match="positive"):
        b.design_defaults(gamma=-1.0)
