"""A small plant for ``fte tune`` tests: two states, an actuator fault and a sensor fault, one
unknown input, a short scenario with one window per fault (issue #18)."""

import casadi as ca

from fte_casadi import PlantBuilder


def plant():
    b = PlantBuilder("tune_small")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([x2 + 0.1 * d, -x1 - 0.8 * x2 + (1.0 + 0.3 * ca.sin(x1) ** 2) * (u + fa) - 0.2 * d])
    b.diffusion([0.0, 0.01 * x2])
    b.outputs([x1, x2, x1 + x2 + fs])
    b.region(x1=(-1.0, 1.0), x2=(-1.0, 1.0))
    b.reference(u=[0.2])
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, Scenario

    return Scenario(
        name="tune_small",
        T=5.0,
        dt=2e-3,
        paths=3,
        faults=(Bias("fa", value=0.3, start=1.5, stop=3.0), Bias("fs", value=0.2, start=3.5, stop=5.0)),
    )
