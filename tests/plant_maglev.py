"""A magnetic levitation rig (a steel ball under an electromagnet; Wong, IEEE Trans. Educ. 29(4), 1986, with
round textbook numbers), written as a new user writes it, twice: in SI units (the gap in metres, 3-9 mm) and
with the gap in millimetres. The same plant: only the units differ, so the two must get the same T-S model.

The magnet pulls with ``k i^2 / x^2`` against gravity; the coil is an R-L circuit driven by a voltage. The
states are deviations from the operating point (gap 6 mm, 1 A), as the automatic sector method builds its
model about x = 0: the gap, the ball's velocity (3 % multiplicative noise on it) and the coil current. An
unknown force acts on the ball, the voltage has an actuator fault and the gap sensor a sensor fault.
"""

from fte_casadi import PlantBuilder

M, G = 0.05, 9.81  # ball mass (kg), gravity (m/s^2)
GAP0, I0 = 6e-3, 1.0  # operating point: gap (m), current (A)
K = M * G * GAP0**2 / I0**2  # magnet constant (N m^2/A^2): the ball floats at the operating point
R, L = 10.0, 0.4  # coil resistance (ohm) and inductance (H)
NOISE = 0.03  # 3 % multiplicative noise on the velocity


def maglev_m():
    """The gap in metres, the velocity in m/s."""
    b = PlantBuilder("maglev")
    x, v, i = b.states("gap_dev", "vel", "cur_dev", units=["m", "m/s", "A"])
    (u,) = b.inputs("volt")
    (d,) = b.unknown_inputs("force")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    pull = K * (I0 + i) ** 2 / (GAP0 + x) ** 2  # N
    b.drift([v, G - pull / M + d / M, (-R * (I0 + i) + R * I0 + u + fa) / L])
    b.diffusion([0.0, NOISE * v, 0.0])
    b.outputs([x + fs, v, i])
    b.region(gap_dev=(-3e-3, 3e-3), vel=(-0.1, 0.1), cur_dev=(-0.5, 0.5))
    return b.build()


def maglev_mm():
    """The same rig with the gap in millimetres and the velocity in mm/s."""
    b = PlantBuilder("maglev")
    x, v, i = b.states("gap_dev", "vel", "cur_dev", units=["mm", "mm/s", "A"])
    (u,) = b.inputs("volt")
    (d,) = b.unknown_inputs("force")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    k_mm, g_mm, gap0_mm = K * 1e6, G * 1e3, GAP0 * 1e3  # N mm^2/A^2, mm/s^2, mm
    pull = k_mm * (I0 + i) ** 2 / (gap0_mm + x) ** 2  # N
    b.drift([v, g_mm - 1e3 * pull / M + 1e3 * d / M, (-R * (I0 + i) + R * I0 + u + fa) / L])
    b.diffusion([0.0, NOISE * v, 0.0])
    b.outputs([x + fs, v, i])
    b.region(gap_dev=(-3.0, 3.0), vel=(-100.0, 100.0), cur_dev=(-0.5, 0.5))
    return b.build()
