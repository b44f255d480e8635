"""A PMSM in dq axes as a new user writes it (SI units, Krause's parameters): a bias on the speed sensor (or i_d's),
the load torque unknown, the stator resistance perturbed by a Brownian motion (0.1 %); no design defaults.
The issue's plant that never certified; it now designs at its defaults (tests/test_fast_plant.py)."""

from fte_casadi import PlantBuilder

R, L, PSI, P, J, B = 0.5, 2e-3, 0.1, 4, 2e-3, 1e-3  # ohm, H, Wb, pole pairs, kg m^2, N m s


def pmsm_speed_sensor(noise: float = 1e-3, sensor: str = "w"):
    b = PlantBuilder(f"pmsm_{sensor}_sensor")
    i_d, i_q, w = b.states("i_d", "i_q", "w", units=["A", "A", "rad/s"])
    v_d, v_q = b.inputs("v_d", "v_q")
    (tl,) = b.unknown_inputs("load")
    (fs,) = b.faults(f"{sensor}_bias", kind="sensor")
    b.drift([
        (-R * i_d + L * w * i_q + v_d) / L,
        (-R * i_q - L * w * i_d - PSI * w + v_q) / L,
        P * (1.5 * P * PSI * i_q - B * w - tl) / J,
    ])  # fmt: skip
    b.diffusion([-noise * R * i_d / L, -noise * R * i_q / L, 0.0])
    b.outputs([i_d + fs if sensor == "i_d" else i_d, i_q, w + fs if sensor == "w" else w])
    b.region(i_d=(-10.0, 10.0), i_q=(-10.0, 10.0), w=(-300.0, 300.0))
    return b.build()


def pmsm_id_sensor():
    """The same motor with the bias on the i_d sensor instead."""
    return pmsm_speed_sensor(sensor="i_d")
