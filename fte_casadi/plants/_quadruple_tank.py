"""Johansson's quadruple-tank process (IEEE TCST 8(3), 2000), minimum-phase setting, as the physics reads.

Four tanks; pump 1 feeds tank 1 (fraction gamma1) and tank 4 (the rest), pump 2 feeds tank 2 (gamma2)
and tank 3; tanks 3 and 4 drain into tanks 1 and 2. Torricelli outflows ``a_i sqrt(2 g h_i)``::

    A1 dh1/dt = -a1 sqrt(2 g h1) + a3 sqrt(2 g h3) + gamma1 k1 v1
    A2 dh2/dt = -a2 sqrt(2 g h2) + a4 sqrt(2 g h4) + gamma2 k2 v2
    A3 dh3/dt = -a3 sqrt(2 g h3) + (1 - gamma2) k2 v2 + d
    A4 dh4/dt = -a4 sqrt(2 g h4) + (1 - gamma1) k1 v1

with the published parameters (levels in cm, time in s, pump voltages in V, flows in cm^3/s). The
plant is written in deviations ``dh`` from the operating point ``h0 = (12.4, 12.7, 1.8, 1.4)`` cm at
``v0 = (3, 3)`` V (the T-S method anchors its premises at 0, where ``sqrt`` of a level would not be
smooth); the operating point is declared, so a loss of effectiveness of a pump scales the voltage
it actually delivers, ``v0 + dv``. The premises (the four square roots' sector quotients) are found
automatically: 4 premises, 16 rules.

Faults and outputs are chosen so that the paper's assumptions hold: all four levels are measured;
``fa`` is an additive fault on pump 1's voltage (a loss of effectiveness in the scenario); ``fs`` a
bias on the level-1 sensor; ``d`` an unknown inflow into tank 3 (cm^3/s). An inflow into tank 1
together with a bias on the level-1 sensor could not be told apart (the outputs see them
identically; ``fte design`` names the pair and the measurement that would separate them).
"""

from __future__ import annotations

import casadi as ca

from ..model import Plant, PlantBuilder

#: Johansson (2000), Table I and the minimum-phase operating point P-
PARAMS = {
    "A1": 28.0, "A2": 32.0, "A3": 28.0, "A4": 32.0,  # cm^2
    "a1": 0.071, "a2": 0.057, "a3": 0.071, "a4": 0.057,  # cm^2
    "g": 981.0, "k1": 3.33, "k2": 3.35, "gamma1": 0.70, "gamma2": 0.60,
}  # fmt: skip
H0 = (12.4, 12.7, 1.8, 1.4)
V0 = (3.0, 3.0)
#: multiplicative level noise (per sqrt(s)) of each tank: 0.1 % of the deviation
NOISE = 1e-3


def quadruple_tank() -> Plant:
    """The quadruple tank in deviations from its minimum-phase operating point (states dh1..dh4 in cm)."""
    p = PARAMS
    b = PlantBuilder("quadruple-tank")
    dh = b.states("dh1", "dh2", "dh3", "dh4", units="cm")
    dv1, dv2 = b.inputs("dv1", "dv2")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")  # pump 1 delivers v0 + dv1 + fa
    (fs,) = b.faults("fs", kind="sensor")  # the level-1 sensor reads dh1 + fs
    h = [h0 + x for h0, x in zip(H0, dh)]
    q = [p[f"a{k + 1}"] * ca.sqrt(2 * p["g"] * h[k]) for k in range(4)]
    v1, v2 = V0[0] + dv1 + fa, V0[1] + dv2
    b.drift(
        [
            (-q[0] + q[2] + p["gamma1"] * p["k1"] * v1) / p["A1"],
            (-q[1] + q[3] + p["gamma2"] * p["k2"] * v2) / p["A2"],
            (-q[2] + (1 - p["gamma2"]) * p["k2"] * v2 + d) / p["A3"],
            (-q[3] + (1 - p["gamma1"]) * p["k1"] * v1) / p["A4"],
        ]
    )
    b.diffusion([NOISE * x for x in dh])
    b.outputs([dh[0] + fs, dh[1], dh[2], dh[3]], names=["y1", "y2", "y3", "y4"])
    # the levels stay within the tanks (h > 0) and within the operating range of the linear pumps
    b.region(dh1=(-6.0, 6.0), dh2=(-6.0, 6.0), dh3=(-1.5, 1.5), dh4=(-1.2, 1.2))
    b.operating_point(u=list(V0))
    b.input_limits(dv1=(-V0[0], 10.0 - V0[0]), dv2=(-V0[1], 10.0 - V0[1]))  # pumps 0-10 V
    b.initial_state([0.0, 0.0, 0.0, 0.0])
    b.parameters(**p)
    return b.build()


def scenario():
    """Pump 1 loses 30 % of its effectiveness for 150 <= t < 350 s; the level-1 sensor reads 1 cm high for
    450 <= t < 650 s; an unknown inflow into tank 3, uniform in [-0.5, 0.5] cm^3/s each step; x0 = the
    operating point plus Gaussian noise (std 0.1 cm); T = 800 s, dt = 0.1 s, 10 paths."""
    from ..sim import Bias, LossOfEffectiveness, Scenario, UniformNoise

    return Scenario(
        name="quadruple-tank",
        T=800.0,
        dt=0.1,
        faults=(
            LossOfEffectiveness("fa", loss=0.3, start=150.0, stop=350.0),
            Bias("fs", value=1.0, start=450.0, stop=650.0),
        ),
        unknown_input=UniformNoise(0.5),
        x0=(0.0, 0.0, 0.0, 0.0),
        x0_noise=0.1,
        paths=10,
    )
