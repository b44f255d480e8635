"""Three-tank DTS200 of Section 6.2 — Torricelli outflows, linearised at three operating points.

Levels h1..h3 in cm, pump flows Q1, Q2 in cm^3/s, time in s. The Jacobians at the operating
points (15, 10, 12.5), (20, 10, 15), (25, 10, 17.5) cm reproduce the paper's printed A_i to
all printed digits; the diffusion is the paper's W_i blended by the memberships.
"""

from __future__ import annotations

import casadi as ca

from ..model import Plant, PlantBuilder

PARAMS = {"A": 154.0, "Sn": 0.5, "g": 981.0, "az13": 0.475, "az32": 0.475, "az20": 0.598}
POINTS = ((15.0, 10.0, 12.5), (20.0, 10.0, 15.0), (25.0, 10.0, 17.5))
BD = (0.1, -0.2, 0.5)
W_RULES = (
    ((-0.001, 0.0, -0.002), (0.0, -0.001, 0.003), (-0.002, 0.003, 0.005)),
    ((-0.002, 0.0, 0.001), (0.0, 0.002, -0.004), (0.001, 0.005, -0.003)),
    ((0.003, 0.0, -0.001), (0.0, -0.001, 0.002), (0.002, 0.0, 0.001)),
)


def _flow(az: float, sn: float, g: float, dh: ca.SX) -> ca.SX:
    """Torricelli flow ``az Sn sgn(dh) sqrt(2 g |dh|)``."""
    return az * sn * ca.sign(dh) * ca.sqrt(2 * g * ca.fabs(dh))


def three_tank() -> Plant:
    """The paper's three-tank system (states h1, h2, h3; inputs Q1, Q2; pump-2 fault)."""
    p = PARAMS
    b = PlantBuilder("three-tank")
    h1, h2, h3 = b.states("h1", "h2", "h3", units="cm")
    q1, q2 = b.inputs("Q1", "Q2")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")  # pump 2 delivers Q2 + fa
    hs = b.operating_points(h1, POINTS)
    q13 = _flow(p["az13"], p["Sn"], p["g"], h1 - h3)
    q32 = _flow(p["az32"], p["Sn"], p["g"], h3 - h2)
    q20 = _flow(p["az20"], p["Sn"], p["g"], h2)
    b.drift(
        [
            (q1 - q13) / p["A"] + BD[0] * d,
            (q2 + fa + q32 - q20) / p["A"] + BD[1] * d,
            (q13 - q32) / p["A"] + BD[2] * d,
        ]
    )
    x = ca.vertcat(h1, h2, h3)
    g = ca.SX.zeros(3)
    for hk, Wk in zip(hs, W_RULES):
        g += hk * ca.mtimes(ca.SX(ca.DM(Wk)), x)
    b.diffusion([g[0], g[1], g[2]])
    b.outputs([h1, h2], names=["h1", "h2"])
    b.region(h1=(15.0, 25.0), h2=(5.0, 15.0), h3=(10.0, 20.0))
    b.reference(x=list(POINTS[1]))
    b.input_limits(
        Q1=(0.0, 100.0), Q2=(0.0, 100.0)
    )  # the DTS200's pumps: no reverse flow, at most ~100 cm^3/s
    b.initial_state([20.0, 10.0, 15.0])
    # Section 6.2 has gamma = 1, gamma1 = 0.9, sigma = 5, rho0 = eps = 1e-4 (delta not given: = eps). The
    # defaults are `fte tune`'s (rounded to 3 digits): `fte tune three-tank --trials 60 --seed 1` from
    # Section 6.2's parameters chose its trial 36, and the same command from that design its trial 39;
    # each better than the one before on fault error, false alarms and FTC ratio. The same command from that
    # design, its tiers judging each output too, chose its trial 9 (kappa doubled; the decay rate and boundary
    # layer follow it), the balanced rule's choice among the front's designs that measure no output worse than
    # without tolerant control (h1 0.992 against the round before's 1.008; docs/tune.md)
    b.design_defaults(gamma=0.335, gamma1=0.0816, sigma=0.217, delta=1e-4, epsilon=2.39e-4, alpha=0.0179,
                      kappa=1.71e5, boundary_layer=0.0147)  # fmt: skip
    b.parameters(**p)
    return b.build()


def scenario():
    """Section 6.2's experiment: pump 2 delivers 10 cm^3/s less for 200 <= t < 400 s (additive ``fa = -10``),
    d uniform in [-0.1, 0.1] each step, x0 = [20, 10, 15] cm plus Gaussian noise (std 0.2 cm), T = 600 s,
    dt = 10 ms (well below the designs' ts_max; the simulator lowers it if a design needs), 10 paths."""
    from ..sim import Bias, Scenario, UniformNoise

    return Scenario(
        name="three-tank",
        T=600.0,
        dt=1e-2,
        faults=(Bias("fa", value=-10.0, start=200.0, stop=400.0),),
        unknown_input=UniformNoise(0.1),
        x0=(20.0, 10.0, 15.0),
        x0_noise=0.2,
        paths=10,
    )
