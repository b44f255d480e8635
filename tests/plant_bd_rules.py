"""A cart-pole-like plant whose unknown input enters through a premise-dependent gain, so that Bd_i
differs between rules (issue #19 item 4): a torque disturbance ``tau`` drives the pole's rate and,
through ``cos(theta)``, the cart's velocity. Decoupling both directions leaves the pole's angle
unobservable (assumption (4) fails with s = 0 repeated); H decoupling the mean direction and the
sliding term attenuating the rest (Remark 5) restores it.
"""

import casadi as ca

from fte_casadi import PlantBuilder


def plant():
    b = PlantBuilder("bd_rules")
    pos, vel, theta, omega = b.states("pos", "vel", "theta", "omega")
    (u,) = b.inputs("u")
    (tau,) = b.unknown_inputs("tau")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift(
        [
            vel,
            -pos - vel + u + fa + ca.cos(theta) * tau,
            omega,
            -2.0 * theta - omega + 0.5 * pos + tau,
        ]
    )
    b.diffusion([0.0, 0.01 * vel, 0.0, 0.0])
    b.outputs([pos, vel, theta, omega])
    b.region(pos=(-1.0, 1.0), vel=(-1.0, 1.0), theta=(-1.2, 1.2), omega=(-2.0, 2.0))
    b.reference(u=[0.2])
    return b.build()


def scenario(d_amplitude: float = 0.5):
    from fte_casadi.sim import Bias, Scenario, Sinusoid

    return Scenario(
        name="bd_rules",
        T=6.0,
        dt=1e-3,
        faults=(Bias("fa", value=0.5, start=2.0, stop=5.0),),
        unknown_input=Sinusoid(amplitude=d_amplitude, frequency=0.4) if d_amplitude else None,
        paths=4,
    )
