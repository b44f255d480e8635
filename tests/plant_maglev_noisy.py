"""A magnetic levitation whose magnet pulls with a force that fluctuates by 3 % (Wong, IEEE Trans. Educ. 29(4),
1986, with round textbook numbers), written as a new user writes it: SI units, no design defaults.

    m x'' = m g - k i^2 / x^2,     L i' = -R i + u

x is the air gap (m), i the coil current (A), u the coil voltage (V). States, in deviations from the
operating point (x*, 0, i*, u*) = (6 mm, 0, 1 A, 10 V): the gap's deviation e (m), the ball's velocity v
(m/s) and the current's deviation j (A). Input: the voltage's deviation du (V; the amplifier delivers
u* + du, declared by ``b.operating_point``, so a loss of effectiveness scales u* + du).

Parameters: m = 0.05 kg, g = 9.81 m/s^2, R = 10 ohm, L = 0.4 H, and the magnet's constant
k = m g x*^2 / i*^2 = 1.7658e-5 N m^2/A^2, so that the ball floats at the operating point. The open loop is
unstable there: the linearisation has eigenvalues +/- sqrt(2 g / x*) = +/- 57.2 1/s and -R / L = -25 1/s.

Brownian perturbation: the magnet's pull fluctuates by 3 % of its deviation from the ball's weight,
0.03 (k i^2 / x^2 - m g) / m in the velocity equation, written factored so that it is exactly zero at the
operating point. Faults: fa, an actuator fault of the coil voltage, and fs, a bias of the gap sensor. Outputs:
the gap sensor's reading (with fs) and the current sensor's, in deviations. No unknown input: with two sensors
and two faults there is no room for one (assumption (2)). Region: gap 5 to 7 mm, |v| <= 0.1 m/s, current 0.75 to
1.25 A (the magnet keeps its authority: at zero current the input reaches nothing).
"""

from fte_casadi import PlantBuilder

MASS, G, R, L = 0.05, 9.81, 10.0, 0.4  # kg, m/s^2, ohm, H
X_STAR, I_STAR = 6e-3, 1.0  # m, A: the operating point
U_STAR = R * I_STAR  # V
K = MASS * G * X_STAR**2 / I_STAR**2  # N m^2 / A^2
NOISE = 0.03  # relative fluctuation of the magnet's pull (per sqrt(s))


def _excess(e, j):
    """(k i^2 / x^2 - m g) / m in m/s^2, factored: k/m (i x* - i* x)(i x* + i* x) / (x x*)^2."""
    i, x = I_STAR + j, X_STAR + e
    return K / MASS * (j * X_STAR - I_STAR * e) * (i * X_STAR + I_STAR * x) / (x * X_STAR) ** 2


def maglev(noise: float = NOISE):
    b = PlantBuilder("maglev_noisy")
    e, v, j = b.states("e", "v", "j", units=["m", "m/s", "A"])
    (du,) = b.inputs("du")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([v, -_excess(e, j), (-R * j + du + fa) / L])
    b.diffusion([0.0, -noise * _excess(e, j), 0.0])
    b.outputs([e + fs, j], names=["gap_dev", "i_dev"], units=["m", "A"])
    b.region(e=(-1e-3, 1e-3), v=(-0.1, 0.1), j=(-0.25, 0.25))
    b.operating_point(u=[U_STAR])
    b.reference(x=[0.0, 0.0, 0.0])
    b.initial_state([0.0, 0.0, 0.0])
    b.input_limits(du=(-U_STAR, 30.0 - U_STAR))  # the amplifier gives 0 to 30 V
    b.parameters(m=MASS, g=G, L=L, R=R, k=K, x_star=X_STAR, i_star=I_STAR, noise=noise)
    return b.build()


def maglev_calm():
    """The same levitation without the pull's noise."""
    return maglev(0.0)


def scenario():
    """T = 2 s at dt = 1e-4 s: a 20 % loss of the coil voltage for 0.5 <= t < 1 s, a 0.2 mm bias of the gap
    sensor for 1.25 <= t < 1.75 s, sensor noise of 10 um on the gap and 5 mA on the current."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario

    return Scenario(
        name="maglev_noisy",
        T=2.0,
        dt=1e-4,
        faults=(
            LossOfEffectiveness("fa", loss=0.2, start=0.5, stop=1.0),
            Bias("fs", value=2e-4, start=1.25, stop=1.75),
        ),
        x0_noise=1e-5,
        paths=8,
        measurement_noise=(1e-5, 5e-3),
    )
