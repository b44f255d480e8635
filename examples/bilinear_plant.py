"""A plant with a bilinear term and a saturation, derived automatically.

    fte derive examples/bilinear_plant.py:bilinear
    fte design examples/bilinear_plant.py:bilinear -o bilinear.json
    fte simulate bilinear.json

``x1 * x2`` and ``tanh(x1)`` are written as they are; ``fte derive`` writes the drift exactly as
``A(z) x + B u + ...`` with two premises, ``x1`` (from ``x1 x2``) and ``tanh(x1)/x1``, hence four
rules, and checks the result against these equations (fidelity at round-off).
"""

import casadi as ca

from fte_casadi import PlantBuilder


def bilinear():
    b = PlantBuilder("bilinear")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift([x2 + 0.1 * d, -x1 * x2 - 2.0 * ca.tanh(x1) - 0.5 * x2 + u + fa - 0.2 * d])
    b.diffusion([0.01 * x1, 0.01 * x2])
    b.outputs([x1, x1 + x2])
    b.region(x1=(-2.0, 2.0), x2=(-2.0, 2.0))
    b.reference(u=[0.0])
    b.initial_state([0.3, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.2, delta=1e-4, epsilon=1e-4)
    return b.build()


def scenario():
    """An actuator bias of 0.5 for 2 <= t < 4 s, d uniform in [-0.05, 0.05], T = 6 s, 8 paths."""
    from fte_casadi.sim import Bias, Scenario, UniformNoise

    return Scenario(name="bilinear", T=6.0, dt=1e-3, faults=(Bias("fa", value=0.5, start=2.0, stop=4.0),),
                    unknown_input=UniformNoise(0.05), x0_noise=0.01, paths=8)  # fmt: skip
