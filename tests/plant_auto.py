"""Plants of the tests of the automatic sector method (issue #10), written as a user would write them.

``manipulator_plain`` is the paper's manipulator exactly as (82) prints it (plain ``sin(theta_l)``,
no premise), with the numbers of fte_casadi/plants/_manipulator.py; ``linear`` has no nonlinear term
(the example pendulum linearised).
Each can be given to the CLI as ``tests/plant_auto.py:manipulator_plain``; ``too_few_outputs`` fails assumption (2).
"""

import casadi as ca

from fte_casadi import PlantBuilder
from fte_casadi.plants._manipulator import ALPHA_D, PARAMS, W


def manipulator_plain():
    """The manipulator exactly as (82) prints it: plain sin(theta_l), no premise."""
    p, a, w = PARAMS, ALPHA_D, W
    b = PlantBuilder("manipulator-plain")
    th_m, w_m, th_l, w_l = b.states("theta_m", "w_m", "theta_l", "w_l")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([w_m + a[0] * d, p["k_Jm"] * (th_l - th_m) - p["G_Jm"] * w_m + p["ktau_Jm"] * (u + fa) + a[1] * d,
             w_l + a[2] * d, -p["k_Jl"] * (th_l - th_m) - p["mgh_Jl"] * ca.sin(th_l) + a[3] * d])  # fmt: skip
    b.diffusion([w["W12"] * w_m, w["W23"] * th_l + w["W21"] * th_m + w["W22"] * w_m, w["W34"] * w_l,
                 w["W43"] * th_l + w["W41"] * th_m + w["Ws"] * ca.sin(th_l)])  # fmt: skip
    b.outputs([th_m + fs, w_m, th_l])
    b.region(
        theta_l=(-2 * ca.pi, 2 * ca.pi), theta_m=(-2 * ca.pi, 2 * ca.pi), w_m=(-5.0, 5.0), w_l=(-5.0, 5.0)
    )
    b.reference(u=[2.0])
    b.initial_state([0.1, 0.05, 0.02, 0.03])
    # the built-in manipulator's defaults (fte tune's, issue #18)
    b.design_defaults(gamma=2.49, gamma1=0.0176, sigma=0.151, delta=1e-5, epsilon=8.4e-6, alpha=1.48, kappa=1.73e4,
                      bound_weight=0.475)  # fmt: skip
    return b.build()


def linear():
    """The pendulum of examples/ linearised about theta = 0 (sin(theta) -> theta): one rule."""
    b = PlantBuilder("linear")
    th, om = b.states("theta", "omega")
    (u,) = b.inputs("torque")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([om + 0.2 * d, -9.81 * th - 0.8 * om + 2.0 * (u + fa) - 0.5 * d])
    b.diffusion([0.0, 0.01 * om + 0.005 * th])
    b.outputs([th + fs, om, th + om])
    b.reference(u=[0.5])
    b.initial_state([0.2, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.5, delta=1e-4, epsilon=1e-4)
    return b.build()


def linear_scenario():
    """The pendulum's experiment, shorter: 30 % loss of torque for 2 <= t < 4 s, an angle-sensor bias of
    0.05 rad for 5 <= t < 7 s, d uniform in [-0.1, 0.1]."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(name="linear", T=8.0, dt=1e-3, faults=(LossOfEffectiveness("fa", loss=0.3, start=2.0, stop=4.0),
                    Bias("fs", value=0.05, start=5.0, stop=7.0)), unknown_input=UniformNoise(0.1), x0_noise=0.01,
                    paths=4)  # fmt: skip


def two_state(drift_rows, diff_rows=(0.0, 0.0), region=((-2.0, 2.0), (-2.0, 2.0)), name="p"):
    """``x1' , x2'`` from ``drift_rows(x1, x2, u, fa)``; both states measured."""
    b = PlantBuilder(name)
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    b.drift(drift_rows(x1, x2, u, fa))
    b.diffusion([r(x1, x2) if callable(r) else r for r in diff_rows])
    b.outputs([x1, x2])
    b.region(x1=region[0], x2=region[1])
    return b.build()


def too_few_outputs():
    """Two outputs for an actuator fault, a sensor fault and an unknown input: assumption (2) cannot hold."""
    b = PlantBuilder("few")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([x2, -x1 - x1**3 + u + fa + 0.1 * d])
    b.diffusion([0.0, 0.01 * x1])
    b.outputs([x1 + fs, x2])
    b.region(x1=(-1, 1), x2=(-1, 1))
    return b.build()
