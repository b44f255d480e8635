"""A plant with an unknown input its outputs cannot decouple (issue #19 item 1: Remark 5).

Two states ``x1``, ``x2`` are measured, ``x3`` is not. The unknown input ``gust`` drives the
unmeasured ``x3``, which moves both measured states: ``Cbar Bdbar = 0``, so
``rank(Cbar Bdbar) = 0 < 1 = rank(Bdbar)`` and assumption (1) fails (H can decouple nothing). An
actuator fault ``fa`` acts on the input. The outputs still tell the fault from the gust (``x1``
sees the gust's state, not the fault), so assumption (2) holds; Remark 5's fallback lets the
sliding term attenuate the gust in the observer.
"""

import casadi as ca

from fte_casadi import PlantBuilder


def plant():
    b = PlantBuilder("remark5")
    x1, x2, x3 = b.states("x1", "x2", "x3")
    (u,) = b.inputs("u")
    (gust,) = b.unknown_inputs("gust")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift(
        [
            -x1 + x3,
            -x2 + 0.5 * x1 + 0.8 * x3 - 0.3 * ca.sin(x1) + u + fa,
            -2.0 * x3 + gust,
        ]
    )
    b.diffusion([0.0, 0.01 * x2, 0.0])
    b.outputs([x1, x2])
    b.region(x1=(-1.5, 1.5), x2=(-2.0, 2.0), x3=(-2.0, 2.0))
    b.reference(u=[0.2])
    return b.build()


def scenario(d_amplitude: float = 0.5):
    from fte_casadi.sim import Bias, Scenario, Sinusoid

    return Scenario(
        name="remark5",
        T=6.0,
        dt=1e-3,
        faults=(Bias("fa", value=0.5, start=2.0, stop=5.0),),
        unknown_input=Sinusoid(amplitude=d_amplitude, frequency=0.4) if d_amplitude else None,
        paths=4,
    )
