"""A textbook two-link planar arm in a vertical plane (Spong, Hutchinson & Vidyasagar, Robot Modeling
and Control, 2006, section 7.4.1), written as a new user writes it: ``M(q) ddq + C(q, dq) dq + g(q) = tau``,
solved for ``ddq`` with ``M(q)^-1`` in closed form. Angles are measured from the downward vertical
(``q = 0``: the arm hangs at rest), so gravity enters through ``sin``; viscous friction at both joints.
An unknown disturbance torque ``d`` acts on joint 2 (a payload) and an actuator fault ``fa`` on the
shoulder torque; the four joint states are measured (encoders and their rate sensors).
"""

import casadi as ca

from fte_casadi import PlantBuilder

M1, M2 = 1.0, 1.0  # link masses (kg)
L1 = 1.0  # length of link 1 (m)
LC1, LC2 = 0.5, 0.5  # joint-to-centre-of-mass distances (m)
I1, I2 = 1.0 / 12.0, 1.0 / 12.0  # link inertias about their centres of mass (kg m^2)
G = 9.81
F1, F2 = 0.5, 0.5  # viscous friction (N m s/rad)


def arm():
    b = PlantBuilder("twolink")
    q1, q2, dq1, dq2 = b.states("q1", "q2", "dq1", "dq2", units=["rad", "rad", "rad/s", "rad/s"])
    tau1, tau2 = b.inputs("tau1", "tau2")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    # inertia matrix M(q), Coriolis and centrifugal terms, gravity (Spong's (7.80)-(7.85))
    m11 = M1 * LC1**2 + M2 * (L1**2 + LC2**2 + 2 * L1 * LC2 * ca.cos(q2)) + I1 + I2
    m12 = M2 * (LC2**2 + L1 * LC2 * ca.cos(q2)) + I2
    m22 = M2 * LC2**2 + I2
    h = -M2 * L1 * LC2 * ca.sin(q2)
    c1 = h * dq2 * dq1 + h * (dq1 + dq2) * dq2
    c2 = -h * dq1 * dq1
    g1 = (M1 * LC1 + M2 * L1) * G * ca.sin(q1) + M2 * LC2 * G * ca.sin(q1 + q2)
    g2 = M2 * LC2 * G * ca.sin(q1 + q2)
    det = m11 * m22 - m12 * m12
    r1 = tau1 + fa - c1 - g1 - F1 * dq1
    r2 = tau2 + d - c2 - g2 - F2 * dq2
    ddq1 = (m22 * r1 - m12 * r2) / det
    ddq2 = (-m12 * r1 + m11 * r2) / det
    b.drift([dq1, dq2, ddq1, ddq2])
    b.diffusion([0.0, 0.0, 0.01 * dq1, 0.01 * dq2])
    b.outputs([q1, q2, dq1, dq2])
    b.region(q1=(-1.0, 1.0), q2=(-1.0, 1.0), dq1=(-2.0, 2.0), dq2=(-2.0, 2.0))
    b.initial_state([0.2, -0.1, 0.0, 0.0])
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, Scenario, UniformNoise

    return Scenario(
        name="twolink",
        T=6.0,
        dt=1e-3,
        faults=(Bias("fa", value=2.0, start=2.0, stop=4.0),),
        unknown_input=UniformNoise(0.2),
        x0=(0.2, -0.1, 0.0, 0.0),
        x0_noise=0.01,
    )
