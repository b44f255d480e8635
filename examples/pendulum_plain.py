"""Your own plant, written as the physics reads: a motor-driven pendulum with a plain sin(theta).

    fte derive examples/pendulum_plain.py:pendulum
    fte design examples/pendulum_plain.py:pendulum -o pendulum.json
    fte simulate pendulum.json --paths 20
    fte codegen pendulum.json --out pendulum_c

No premise is declared: ``fte derive`` finds it in the equations (sector nonlinearity; here the
single premise sin(theta)/theta over |theta| <= pi, shared by the drift and the diffusion, so two
rules). The angle and rate are measured; an actuator fault fa adds to the motor torque and a
sensor fault fs to the angle reading; d is an unknown input and the damping is perturbed by the
Brownian motion. ``examples/pendulum_plant.py`` is the same plant with the premise written by hand.
"""

import casadi as ca

from fte_casadi import PlantBuilder


def pendulum():
    g_l, c, b_u = 9.81, 0.8, 2.0  # g/l [1/s^2], damping [1/s], input gain [rad/s^2 per N m]
    b = PlantBuilder("pendulum-plain")
    th, om = b.states("theta", "omega", units=["rad", "rad/s"])
    (u,) = b.inputs("torque")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([om + 0.2 * d, -g_l * ca.sin(th) - c * om + b_u * (u + fa) - 0.5 * d])
    b.diffusion([0.0, 0.01 * om + 0.005 * ca.sin(th)])
    b.outputs([th + fs, om, th + om], names=["theta", "omega", "theta_plus_omega"])
    b.region(theta=(-ca.pi, ca.pi), omega=(-4.0, 4.0))
    b.reference(u=[0.5])
    b.initial_state([0.2, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.5, delta=1e-4, epsilon=1e-4)
    return b.build()


def scenario():
    """30 % loss of torque for 3 <= t < 6 s, an angle-sensor bias of 0.05 rad for 8 <= t < 11 s,
    d uniform in [-0.1, 0.1], T = 14 s, 10 paths."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="pendulum-plain",
        T=14.0,
        dt=1e-3,
        faults=(
            LossOfEffectiveness("fa", loss=0.3, start=3.0, stop=6.0),
            Bias("fs", value=0.05, start=8.0, stop=11.0),
        ),
        unknown_input=UniformNoise(0.1),
        x0_noise=0.01,
        paths=10,
    )
