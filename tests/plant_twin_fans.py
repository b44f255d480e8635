"""Two fans cooling one block, written as a new user writes it: both blow on the block (T1), fan 2 also,
weakly, on the sensor housing (T2); an unknown heat flow into the coolant (T3); a loss fault on each fan;
every temperature measured; no design defaults. The outputs tell the two fan faults apart only through
``leak``: at 2e-4 the design is refused and the refusal names the faults (tests/test_design_causes.py)."""

from fte_casadi import PlantBuilder


def fans(leak: float = 2e-4, both: bool = True):
    pb = PlantBuilder("fans" if both else "fans_one_fault")
    T1, T2, T3 = pb.states("T1", "T2", "T3", units=["K", "K", "K"])
    u1, u2 = pb.inputs("fan1", "fan2")
    (d,) = pb.unknown_inputs("heat")
    if both:
        f1, f2 = pb.faults("fan1_loss", "fan2_loss", kind="actuator")
    else:
        (f1,), f2 = pb.faults("fan1_loss", kind="actuator"), 0.0
    cooling = 0.05 + 1e-4 * T1**2  # convection grows with the temperature difference
    pb.drift([
        -cooling * T1 - 0.5 * (u1 + f1) - 0.5 * (u2 + f2) + 0.3 * T2 + 0.2 * T3,
        -0.2 * T2 + 0.1 * T1 - leak * (u2 + f2),
        -0.1 * T3 + 0.05 * T1 + d,
    ])  # fmt: skip
    pb.outputs([T1, T2, T3])
    pb.region(T1=(-10.0, 10.0), T2=(-10.0, 10.0), T3=(-10.0, 10.0))
    return pb.build()


def fans_alike():
    return fans(2e-4)


def fans_one_fault():
    """The same fans with one fault for both (the advice of the refusal)."""
    return fans(2e-4, both=False)
