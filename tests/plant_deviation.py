"""A plant written in deviations from an operating point (issue #21 item 4): pump at 3 + u."""

from fte_casadi import PlantBuilder


def plant(op=True):
    b = PlantBuilder("deviation")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("pump")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift([x2 + 0.1 * d, -x1 - 0.5 * x2 + 2.0 * (u + fa) - 0.2 * d])
    b.diffusion([0.0, 0.01 * x2])
    b.outputs([x1, x2])
    b.region(x1=(-1.0, 1.0), x2=(-1.0, 1.0))
    if op:
        b.operating_point(u=[3.0])
    return b.build()


def plain():
    return plant(op=False)


def scenario():
    from fte_casadi.sim import LossOfEffectiveness, Scenario

    return Scenario(
        name="deviation", T=4.0, dt=1e-3, faults=(LossOfEffectiveness("fa", loss=0.3, start=1.0, stop=3.0),)
    )
