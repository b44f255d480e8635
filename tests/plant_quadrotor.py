"""A quadrotor, written as a new user writes it from the README: Newton-Euler rigid body, ZYX Euler angles
(roll phi, pitch theta, yaw psi), SI units, the parameters of Luukkonen, *Modelling and control of quadcopter*
(Aalto University, 2011). The inputs are the total thrust along the body z axis and the three body torques;
the position and velocity are in the world frame (z up), the body rates in the body frame.

    m dv/dt = R(phi, theta, psi) [0, 0, T + fa] - m g e3 - A_d v + [d, 0, 0]
    [phi, theta, psi]' = W(phi, theta) [p, q, r]     (tan(theta) and 1/cos(theta))
    I dw/dt = -w x (I w) + tau

An unknown horizontal wind force d acts along x, the thrust has an actuator fault fa (a worn rotor set) and
the barometric altimeter a sensor fault fs; the vertical velocity has 3 % multiplicative noise. Every state is
measured (GPS position and velocity, an attitude estimate, gyroscopes), the altitude twice (GPS and barometer:
a bias of the only altitude sensor could not be told from the altitude itself, which no other state feels).
"""

import casadi as ca

from fte_casadi import PlantBuilder

M, G = 0.468, 9.81  # mass (kg), gravity (m/s^2)
IXX, IYY, IZZ = 4.856e-3, 4.856e-3, 8.801e-3  # inertia (kg m^2)
DRAG = 0.25  # linear drag (kg/s), the same on each axis
NOISE = 0.03  # 3 % multiplicative noise on the vertical velocity


def quadrotor():
    b = PlantBuilder("quadrotor")
    px, py, pz, vx, vy, vz, phi, theta, psi, p, q, r = b.states(
        "px", "py", "pz", "vx", "vy", "vz", "phi", "theta", "psi", "p", "q", "r",
        units=["m", "m", "m", "m/s", "m/s", "m/s", "rad", "rad", "rad", "rad/s", "rad/s", "rad/s"],
    )  # fmt: skip
    thrust, tau_phi, tau_theta, tau_psi = b.inputs("thrust", "tau_phi", "tau_theta", "tau_psi")
    (d,) = b.unknown_inputs("wind")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    cf, sf, ct, st, cp, sp = ca.cos(phi), ca.sin(phi), ca.cos(theta), ca.sin(theta), ca.cos(psi), ca.sin(psi)
    # body z axis in the world frame: the third column of R = Rz(psi) Ry(theta) Rx(phi)
    zb = [cf * st * cp + sf * sp, cf * st * sp - sf * cp, cf * ct]
    force = thrust + fa
    b.drift([
        vx, vy, vz,
        (zb[0] * force - DRAG * vx + d) / M,
        (zb[1] * force - DRAG * vy) / M,
        (zb[2] * force - DRAG * vz) / M - G,
        p + sf * ca.tan(theta) * q + cf * ca.tan(theta) * r,
        cf * q - sf * r,
        sf / ct * q + cf / ct * r,
        ((IYY - IZZ) * q * r + tau_phi) / IXX,
        ((IZZ - IXX) * p * r + tau_theta) / IYY,
        ((IXX - IYY) * p * q + tau_psi) / IZZ,
    ])  # fmt: skip
    b.diffusion([0.0] * 5 + [NOISE * vz] + [0.0] * 6)
    b.outputs([px, py, pz, pz + fs, vx, vy, vz, phi, theta, psi, p, q, r])
    b.region(px=(-5.0, 5.0), py=(-5.0, 5.0), pz=(-5.0, 5.0), vx=(-3.0, 3.0), vy=(-3.0, 3.0), vz=(-3.0, 3.0),
             phi=(-0.5, 0.5), theta=(-0.5, 0.5), psi=(-ca.pi, ca.pi), p=(-2.0, 2.0), q=(-2.0, 2.0), r=(-2.0, 2.0))  # fmt: skip
    b.reference(u=[M * G, 0.0, 0.0, 0.0])  # hover
    return b.build()


def scenario():
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="quadrotor",
        T=12.0,
        dt=1e-3,
        faults=(
            LossOfEffectiveness("fa", loss=0.2, start=2.0, stop=5.0),  # the rotors deliver 80 % of the thrust
            Bias("fs", value=0.3, start=7.0, stop=10.0),  # the altimeter reads 0.3 m too much
        ),
        unknown_input=UniformNoise(0.05),  # wind gusts up to 0.05 N
        x0_noise=0.01,
    )
