"""A two-degree-of-freedom helicopter (Quanser's 2 DOF Helicopter: a body on a pivot, pitch by a front rotor,
yaw by a back rotor, each rotor's torque also acting on the other axis), written as a new user writes it: SI
units, the maker's round parameters, no design defaults.

    (J_p + m l^2) theta'' = K_pp V_p + K_py V_y - m g l cos(theta) - B_p theta'
    (J_y + m l^2 cos(theta)^2) psi'' = K_yp V_p + K_yy V_y - B_y psi' + d

theta is the pitch (rad, 0 horizontal), psi the yaw (rad), V_p and V_y the front and back motor voltages (V),
d a torque of the wind on the yaw axis (N m, the unknown input). The centrifugal and Coriolis terms
(``m l^2 sin cos psi'^2`` and ``2 m l^2 sin cos theta' psi'``) are left out: at the rates of this region
(|theta'|, |psi'| <= 1 rad/s) they stay below 0.05 N m, a tenth of the gravity torque's change over the region.

Parameters: m = 1.39 kg (moving mass), l = 0.186 m (pivot to centre of mass), J_p = 0.0384 kg m^2,
J_y = 0.0432 kg m^2, B_p = 0.8 N m s/rad, B_y = 0.318 N m s/rad (viscous damping), thrust-torque gains
K_pp = 0.204, K_py = 0.0068, K_yp = 0.0219, K_yy = 0.072 N m/V, g = 9.81 m/s^2.

States, in deviations from the hover (theta, psi, theta', psi') = (theta*, 0, 0, 0), theta* = -0.3 rad (nose
down 17 deg, where gravity restores the pitch: at theta* = 0 its torque is flat, and a pitch encoder's bias could
not be told from a pitch offset): the pitch, the yaw, and their rates. Inputs: the voltages' deviations from the hover voltages (V_p*, V_y*) that hold the body horizontal
with no yaw torque (``b.operating_point``), solved in ``_hover``. Brownian perturbation: the rotors' wash
makes the aerodynamic damping fluctuate by 3 %: ``0.03 B_p theta' / (J_p + m l^2)`` and
``0.03 B_y psi' / (J_y + m l^2 cos^2)`` in the rates' equations. Faults: fa, an actuator fault of the front
motor, and fs, a bias of the yaw-rate gyro (a bias of the pitch encoder could not be told apart: a pitch offset
held by the front motor's fault, its yaw torque cancelled by the wind, reads zero on a biased encoder). Outputs: the pitch and yaw encoders and a yaw-rate gyro.
"""

import casadi as ca
import numpy as np

from fte_casadi import PlantBuilder

MASS, ELL, G = 1.39, 0.186, 9.81  # kg, m, m/s^2
J_P, J_Y, B_P, B_Y = 0.0384, 0.0432, 0.8, 0.318  # kg m^2, kg m^2, N m s/rad, N m s/rad
K_PP, K_PY, K_YP, K_YY = 0.204, 0.0068, 0.0219, 0.072  # N m/V
NOISE = 0.03  # relative fluctuation of the aerodynamic damping (per sqrt(s))
THETA_STAR = -0.3  # rad: the hover pitch, nose down (17 deg)


def _hover() -> np.ndarray:
    """The voltages (V_p*, V_y*) holding theta* with no yaw torque: K [V_p; V_y] = [m g l cos(theta*); 0]."""
    return np.linalg.solve(
        np.array([[K_PP, K_PY], [K_YP, K_YY]]), np.array([MASS * G * ELL * np.cos(THETA_STAR), 0.0])
    )


def helicopter(noise: float = NOISE):
    b = PlantBuilder("helicopter")
    th, psi, om_p, om_y = b.states(
        "theta", "psi", "omega_p", "omega_y", units=["rad", "rad", "rad/s", "rad/s"]
    )
    vp, vy = b.inputs("dV_p", "dV_y")
    (d,) = b.unknown_inputs("wind")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    jp = J_P + MASS * ELL**2
    jy = J_Y + MASS * ELL**2 * ca.cos(THETA_STAR + th) ** 2
    # the gravity torque's change from the hover pitch (the hover voltages hold m g l cos(theta*))
    gravity = MASS * G * ELL * (np.cos(THETA_STAR) - ca.cos(THETA_STAR + th))
    pitch = K_PP * (vp + fa) + K_PY * vy + gravity - B_P * om_p
    yaw = K_YP * (vp + fa) + K_YY * vy - B_Y * om_y + d
    b.drift([om_p, om_y, pitch / jp, yaw / jy])
    b.diffusion([0.0, 0.0, -noise * B_P * om_p / jp, -noise * B_Y * om_y / jy])
    b.outputs([th, psi, om_y + fs], names=["theta_enc", "psi_enc", "gyro_y"], units=["rad", "rad", "rad/s"])
    b.region(theta=(-0.5, 0.5), psi=(-1.0, 1.0), omega_p=(-1.0, 1.0), omega_y=(-1.0, 1.0))
    b.operating_point(u=list(_hover()))
    b.reference(x=[0.0, 0.0, 0.0, 0.0])
    b.initial_state([0.0, 0.0, 0.0, 0.0])
    b.parameters(theta_star=THETA_STAR, m=MASS, l=ELL, J_p=J_P, J_y=J_Y, B_p=B_P, B_y=B_Y, K_pp=K_PP, K_py=K_PY, K_yp=K_YP, K_yy=K_YY,
                 noise=noise)  # fmt: skip
    return b.build()


def helicopter_calm():
    """The same helicopter without the damping's noise."""
    return helicopter(0.0)


def scenario():
    """T = 10 s at dt = 1e-3 s: a 25 % loss of the front motor for 2 <= t < 4 s, a 0.05 rad/s bias of the yaw-rate
    gyro for 6 <= t < 8 s, gusts of wind uniform in +/- 0.05 N m, sensor noise of 1 mrad on the encoders and
    5 mrad/s on the gyro."""
    from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="helicopter",
        T=10.0,
        dt=1e-3,
        faults=(
            LossOfEffectiveness("fa", loss=0.25, start=2.0, stop=4.0),
            Bias("fs", value=0.05, start=6.0, stop=8.0),
        ),
        unknown_input=UniformNoise(0.05),
        x0=(0.05, 0.0, 0.0, 0.0),
        x0_noise=0.01,
        paths=8,
        measurement_noise=(1e-3, 1e-3, 5e-3),
    )
