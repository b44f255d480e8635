"""A scalable family: a chain of n first-order stages with rates 1 + k/10, q of the couplings
through ``sin`` (each a premise found automatically, so 2^q rules), one input, one unknown input at both
ends, an actuator fault on the input and a sensor fault on the first of n + 1 outputs; no design
defaults. The couplings run x_n -> x_1 -> x_2 -> ...: the first q of them are nonlinear."""

import casadi as ca

from fte_casadi.model import PlantBuilder


def chain(n: int = 4, q: int = 1):
    if not 0 <= q <= n:
        raise ValueError(f"q must be within 0..n = {n}; got {q}")
    b = PlantBuilder(f"chain{n}-{q}")
    x = b.states(*[f"x{k + 1}" for k in range(n)])
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    drift = []
    for k in range(n):
        c = x[k - 1]  # the stage before (x_n for the first: a ring)
        coupling = 0.8 * ca.sin(c) if k < q else 0.8 * c
        if k == 0:
            coupling = 0.25 * coupling  # a weak feedback from the last stage
        rate = -(1.0 + 0.1 * k) * x[k] + coupling
        if k == 0:
            rate += (u + fa) + 0.5 * d
        if k == n - 1:
            rate += 0.3 * d
        drift.append(rate)
    b.drift(drift)
    b.diffusion([0.01 * xk for xk in x])
    b.outputs([x[0] + fs] + list(x))
    b.region(**{f"x{k + 1}": (-1.0, 1.0) for k in range(n)})
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, Scenario

    return Scenario(
        name="chain",
        T=10.0,
        dt=1e-3,
        faults=(Bias("fa", value=0.5, start=2.0, stop=5.0), Bias("fs", value=0.2, start=6.0, stop=9.0)),
    )
