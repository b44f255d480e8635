"""A plant whose input gain depends on the state while its actuator fault enters with a constant
direction, so that -pinv(B_i) Bf_i differs between rules (issue #19 item 3: Kf scheduled per rule)."""

import casadi as ca

from fte_casadi import PlantBuilder


def plant():
    b = PlantBuilder("kf_rules")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift([x2 + 0.1 * d, -x1 - 0.8 * x2 + (2.0 + ca.cos(x1)) * u + fa - 0.2 * d])
    b.diffusion([0.0, 0.01 * x2])
    b.outputs([x1, x2])
    b.region(x1=(-1.0, 1.0), x2=(-1.0, 1.0))
    b.reference(u=[0.2])
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, Scenario

    return Scenario(name="kf_rules", T=4.0, dt=1e-3, faults=(Bias("fa", value=0.3, start=1.0, stop=3.0),))
