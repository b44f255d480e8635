"""The textbook inverted pendulum on a cart (Tanaka & Wang, Fuzzy Control Systems Design and Analysis,
2001, eq. (2.24)): m = 2 kg, M = 8 kg, 2l = 1 m, a = 1/(m + M); an encoder bias on the angle and a fault
on the force; a 1 ms controller (issue #21)."""

import casadi as ca

from fte_casadi import PlantBuilder

G, M_POLE, M_CART, L = 9.8, 2.0, 8.0, 0.5
A = 1.0 / (M_POLE + M_CART)


def cartpole():
    b = PlantBuilder("cartpole")
    th, om = b.states("theta", "omega", units=["rad", "rad/s"])
    (u,) = b.inputs("force")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    den = 4 * L / 3 - A * M_POLE * L * ca.cos(th) ** 2
    acc = (G * ca.sin(th) - A * M_POLE * L * om**2 * ca.sin(2 * th) / 2 - A * ca.cos(th) * (u + fa)) / den
    b.drift([om + 0.05 * d, acc + 0.1 * d])
    b.diffusion([0.0, 0.005 * om])
    b.outputs([th + fs, om, th])
    b.region(theta=(-1.0, 1.0), omega=(-2.0, 2.0))
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, Scenario, UniformNoise

    return Scenario(
        name="cartpole",
        T=6.0,
        dt=1e-3,
        faults=(Bias("fa", value=5.0, start=1.0, stop=2.5), Bias("fs", value=0.02, start=3.5, stop=5.0)),
        unknown_input=UniformNoise(0.1),
        x0=(0.1, 0.0),
        x0_noise=0.01,
    )
