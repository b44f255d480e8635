"""Johansson's quadruple tank (minimum-phase setting) in deviations from its operating point, with a
leak into tank 1 and a bias on the level-1 sensor: the outputs cannot tell them apart (issue #19)."""

import casadi as ca

from fte_casadi import PlantBuilder

A1, A2, A3, A4 = 28.0, 32.0, 28.0, 32.0
a1, a2, a3, a4 = 0.071, 0.057, 0.071, 0.057
G, K1, K2, G1, G2 = 981.0, 3.33, 3.35, 0.70, 0.60
H0 = (12.4, 12.7, 1.8, 1.4)
V0 = (3.0, 3.0)


def plant(second_level_1_sensor: bool = False):
    b = PlantBuilder("quadtank_leak")
    dh = b.states("dh1", "dh2", "dh3", "dh4", units=["cm"] * 4)
    v1, v2 = b.inputs("dv1", "dv2")
    (leak,) = b.unknown_inputs("leak")
    (fs,) = b.faults("fs", kind="sensor")
    h = [H0[k] + dh[k] for k in range(4)]
    q = [a * ca.sqrt(2 * G * hk) for a, hk in zip((a1, a2, a3, a4), h)]
    u1, u2 = V0[0] + v1, V0[1] + v2
    b.drift(
        [
            (-q[0] + q[2] + G1 * K1 * u1 + leak) / A1,
            (-q[1] + q[3] + G2 * K2 * u2) / A2,
            (-q[2] + (1 - G2) * K2 * u2) / A3,
            (-q[3] + (1 - G1) * K1 * u1) / A4,
        ]
    )
    b.diffusion([0.0, 0.0, 0.0, 0.0])
    y = [dh[0] + fs, dh[1], dh[2], dh[3]]
    b.outputs(y + [dh[0]] if second_level_1_sensor else y)
    b.region(dh1=(-5.0, 5.0), dh2=(-5.0, 5.0), dh3=(-1.0, 1.0), dh4=(-1.0, 1.0))
    return b.build()


def measured_twice():
    """The same plant with a second level-1 sensor, free of the bias."""
    return plant(second_level_1_sensor=True)
