"""A plant of the tests' own (issue #9): 3 states, two premises, 4 rules, infeasible at its defaults.

Its large output gains (C^T C in LMI (45)) leave room only for sigma < 0.09, while its defaults ask
for sigma = 0.5 (gamma = 2, gamma1 = 0.1): the design must fail with bounds that work.
"""

import casadi as ca

from fte_casadi import PlantBuilder


def tight():
    b = PlantBuilder("tight")
    x1, x2, x3 = b.states("x1", "x2", "x3")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    m1 = b.premise("m1", ca.if_else(ca.fabs(x1) < 1e-6, 1 - x1**2 / 6, ca.sin(x1) / x1), text="sin(x1)/x1")
    m2 = b.premise("m2", ca.cos(x2), text="cos(x2)")
    b.drift([x2 + 0.1 * d, -2 * m1 * x1 - 0.5 * x2 + x3 + 0.2 * d, -x3 + m2 * x1 + 2.0 * (u + fa) + 0.3 * d])
    b.diffusion([0.02 * x1, 0.01 * x2 + 0.01 * m1 * x1, 0.02 * x3])
    b.outputs([4 * x1, 3 * x2, x3])
    b.region(x1=(-3.0, 3.0), x2=(-2.0, 2.0))
    b.reference(u=[0.0])
    b.initial_state([0.2, 0.0, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.5, delta=1e-4, epsilon=1e-4)
    return b.build()
