"""A ball and beam (Hauser, Sastry & Kokotovic, IEEE Trans. Autom. Control 37(3), 1992): a ball rolling on a beam
that a motor tilts; one input for four states, the ball reached only through the beam's angle. Written as a new
user writes it: SI units, textbook parameters, no design defaults.

    (J_b / R_b^2 + m) r'' = m r phi'^2 - m g sin(phi)
    J phi'' = tau - m g r cos(phi)

r is the ball's position along the beam (m, 0 at the pivot), phi the beam's angle (rad), tau the motor torque
(N m). The beam's inertia J includes the motor's; the ball's share of it (``m r^2``) and the Coriolis torque
``2 m r r' phi'`` are left out (below 5 % of J and of the gravity torque in the region). A solid ball:
J_b = 2/5 m R_b^2, so that r'' = 5/7 (r phi'^2 - g sin(phi)).

Parameters: m = 0.05 kg, J = 0.02 kg m^2, g = 9.81 m/s^2. Region: |r| <= 0.3 m, |r'| <= 0.5 m/s,
|phi| <= 0.25 rad, |phi'| <= 1 rad/s. The open loop at rest (r = 0, phi = 0) is a chain of integrators
with the ball's weight coupling back: eigenvalues 0 (four times, slightly split by ``m g / J``).

Brownian perturbation: the ball's rolling fluctuates by 3 % of its gravity term, ``-0.03 * 5/7 g sin(phi)``
in r''. Faults: fa, an actuator fault of the motor torque, and fs, a bias of the beam's encoder (a bias of the ball's
position sensor could not be told apart: a ball held off the pivot by a torque fault reads zero on a biased
sensor). Outputs: the ball's position (a resistive wire under the ball) and the beam's angle (with fs).
"""

import casadi as ca

from fte_casadi import PlantBuilder

MASS, J_BEAM, G = 0.05, 0.02, 9.81  # kg, kg m^2, m/s^2
ROLL = 5.0 / 7.0  # m / (J_b / R_b^2 + m) for a solid ball
NOISE = 0.03  # relative fluctuation of the ball's gravity term (per sqrt(s))


def ballbeam(noise: float = NOISE):
    b = PlantBuilder("ballbeam")
    r, v, phi, om = b.states("r", "v", "phi", "omega", units=["m", "m/s", "rad", "rad/s"])
    (tau,) = b.inputs("tau")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([v, ROLL * (r * om**2 - G * ca.sin(phi)), om, (tau + fa - MASS * G * r * ca.cos(phi)) / J_BEAM])
    b.diffusion([0.0, -noise * ROLL * G * ca.sin(phi), 0.0, 0.0])
    b.outputs([r, phi + fs], names=["r_sensor", "phi_enc"], units=["m", "rad"])
    b.region(r=(-0.3, 0.3), v=(-0.5, 0.5), phi=(-0.25, 0.25), omega=(-1.0, 1.0))
    b.reference(x=[0.0, 0.0, 0.0, 0.0])
    b.initial_state([0.05, 0.0, 0.0, 0.0])
    b.parameters(m=MASS, J=J_BEAM, g=G, noise=noise)
    return b.build()


def ballbeam_calm():
    """The same ball and beam without the rolling noise."""
    return ballbeam(0.0)


def scenario():
    """T = 10 s at dt = 1e-3 s: a constant torque fault of -0.02 N m for 2 <= t < 4 s, a 0.02 rad bias of the
    encoder for 6 <= t < 8 s, sensor noise of 1 mm on the position and 1 mrad on the angle."""
    from fte_casadi.sim import Bias, Scenario

    return Scenario(
        name="ballbeam",
        T=10.0,
        dt=1e-3,
        faults=(Bias("fa", value=-0.02, start=2.0, stop=4.0), Bias("fs", value=0.02, start=6.0, stop=8.0)),
        x0_noise=0.005,
        paths=8,
        measurement_noise=(1e-3, 1e-3),
    )
