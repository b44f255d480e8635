"""A mass on a hardening (Duffing) spring with noisy position and velocity sensors: a plant of a user's own
for the detection tests (tests/test_detectability.py) and docs/interface.md's measurements.

    m ddx = -k x - k3 x^3 - c dx + b (u + fa) + d

The cubic spring is covered by the premise ``x^2`` over ``|x| <= 2``; the position sensor carries a fault
``fs``, the force an actuator fault ``fa``; the three readings (position, velocity and their sum) carry white
noise (the scenario's ``measurement_noise``), so every detection threshold is set with it.
"""

from fte_casadi import PlantBuilder


def duffing():
    # spring [1/s^2], cubic spring [1/(m^2 s^2)], damping [1/s], input gain
    k, k3, c, b_u = 4.0, 1.0, 1.2, 2.0
    b = PlantBuilder("duffing")
    x, v = b.states("x", "v", units=["m", "m/s"])
    (u,) = b.inputs("force")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([v + 0.2 * d, -k * x - k3 * x**3 - c * v + b_u * (u + fa) - 0.5 * d])
    b.diffusion([0.0, 0.01 * v + 0.005 * x])
    b.outputs([x + fs, v, x + v], names=["x_read", "v_read", "x_plus_v"])
    b.region(x=(-2.0, 2.0), v=(-4.0, 4.0))
    b.reference(u=[0.5])
    b.initial_state([0.2, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.5, delta=1e-4, epsilon=1e-4)
    b.parameters(k=k, k3=k3, c=c, b_u=b_u)
    return b.build()


def scenario():
    """A 30 % loss of force for 3 <= t < 6 s, a position-sensor bias of 0.05 m for 8 <= t < 11 s, d uniform in
    [-0.1, 0.1], white noise of std 0.005 m, 0.02 m/s and 0.01 m on the three readings; T = 14 s, 10 paths."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="duffing",
        T=14.0,
        dt=1e-3,
        faults=(
            LossOfEffectiveness("fa", loss=0.3, start=3.0, stop=6.0),
            Bias("fs", value=0.05, start=8.0, stop=11.0),
        ),
        unknown_input=UniformNoise(0.1),
        x0_noise=0.01,
        paths=10,
        measurement_noise=(0.005, 0.02, 0.01),
    )
