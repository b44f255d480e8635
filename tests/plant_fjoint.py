"""Spong's flexible-joint arm, written as a new user writes it (SI units, literature parameters): the link
(q1, w1) and the motor (q2, w2) coupled by a spring, the spring's stiffness perturbed by a Brownian motion
(``noise`` x its torque), an unknown torque d on the link, an actuator fault on the motor torque and a
sensor fault on the motor's tachometer; no design defaults."""

import casadi as ca

from fte_casadi import PlantBuilder

I_L, J_M, K, MGL, B_M = 0.031, 0.004, 7.13, 0.8, 0.007


def fjoint(noise: float = 0.001):
    pb = PlantBuilder("fjoint")
    q1, w1, q2, w2 = pb.states("q1", "w1", "q2", "w2", units=["rad", "rad/s", "rad", "rad/s"])
    (u,) = pb.inputs("tau")
    (d,) = pb.unknown_inputs("d")
    (fa,) = pb.faults("fa", kind="actuator")
    (fs,) = pb.faults("fs", kind="sensor")
    spring = K * (q1 - q2)
    pb.drift([w1, (-MGL * ca.sin(q1) - spring + d) / I_L, w2, (spring - B_M * w2 + u + fa) / J_M])
    pb.diffusion([0.0, noise * spring / I_L, 0.0, -noise * spring / J_M])
    pb.outputs([q1, q2, w1, w2 + fs])
    pb.region(q1=(-1.5, 1.5), w1=(-10.0, 10.0), q2=(-1.5, 1.5), w2=(-10.0, 10.0))
    pb.reference(u=[0.2])
    return pb.build()


def fjoint_calm():
    """The same arm without the stiffness noise."""
    return fjoint(0.0)
