"""Plants of the tests' own with a non-finite coefficient (tests/test_plant_nonfinite.py).

``nan_plant`` is a pendulum with a NaN in its drift (a parameter read from a file that held none,
say); ``inf_plant`` has an infinite diffusion coefficient; ``nan_parameter`` records a NaN parameter
beside sane equations. Each must be refused by ``build()`` at once, naming the entry and the point.
"""

import casadi as ca

from fte_casadi import PlantBuilder


def _pendulum(drift_gain=-9.8, noise=0.01, params=None):
    b = PlantBuilder("pendulum-nonfinite")
    th, om = b.states("theta", "omega")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    mu = b.premise(
        "mu", ca.if_else(ca.fabs(th) < 1e-4, 1 - th**2 / 6, ca.sin(th) / th), text="sin(theta)/theta"
    )
    b.drift([om + 0.1 * d, drift_gain * mu * th - 0.5 * om + u + fa])
    b.diffusion([noise * om, 0.0])
    b.outputs([th])
    b.region(theta=(-3.0, 3.0), omega=(-2.0, 2.0))
    b.reference(u=[0.0])
    b.initial_state([0.1, 0.0])
    if params:
        b.parameters(**params)
    return b.build()


def nan_plant():
    return _pendulum(drift_gain=float("nan"))


def inf_plant():
    return _pendulum(noise=float("inf"))


def nan_parameter():
    return _pendulum(params={"g": 9.8, "l": float("nan")})
