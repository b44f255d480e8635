"""Single-link manipulator of Section 6.1, equations (82) — written as a user writes a plant.

Sector nonlinearity on the premise ``mu = sin(theta_l) / theta_l`` (1 at theta_l = 0).
The coefficient ratios reproduce the paper's printed A_1, A_2 and B exactly.
"""

from __future__ import annotations

import casadi as ca

from ..model import Plant, PlantBuilder

#: coefficient ratios of (82) (k/Jm, G/Jm, ktau/Jm, k/Jl, mgh/Jl)
PARAMS = {"k_Jm": 48.6, "G_Jm": 1.25, "ktau_Jm": 21.6, "k_Jl": 19.5, "mgh_Jl": 3.33}
#: unknown-input coefficients alpha_d1..alpha_d4
ALPHA_D = (0.1, -0.2, 0.3, 0.5)
#: Brownian parameter perturbations of (82)
W = {
    "W12": 0.0006,
    "W23": 0.001,
    "W21": -0.002,
    "W22": -0.0001,
    "W34": 0.0005,
    "W43": 0.006,
    "W41": -0.0004,
    "Ws": 0.003,
}


def sinc(v: ca.SX) -> ca.SX:
    """``sin(v)/v`` with its removable singularity at 0 filled by the Taylor series.

    Below ``|v| = 1e-4`` the series ``1 - v^2/6 + v^4/120`` is used (its error, below ``v^6/5040 <
    2e-28``, is far under the rounding of a double); above, the quotient is exact to rounding. An ``SX``
    ``if_else`` computes both branches (and so does the generated C), so the quotient divides by
    ``v`` only where ``v`` is away from 0 and by 1 elsewhere: never ``0/0``, even in the branch that is
    thrown away (with floating-point traps on, that 0/0 would stop the controller).
    """
    small = ca.fabs(v) < 1e-4
    den = ca.if_else(small, 1.0, v)  # 0 + v = v exactly where the quotient is kept
    return ca.if_else(small, 1 - v**2 / 6 + v**4 / 120, ca.sin(den) / den)


def manipulator() -> Plant:
    """The paper's single-link manipulator (state theta_m, w_m, theta_l, w_l)."""
    p, a, w = PARAMS, ALPHA_D, W
    b = PlantBuilder("manipulator")
    th_m, w_m, th_l, w_l = b.states(
        "theta_m", "w_m", "theta_l", "w_l", units=["rad", "rad/s", "rad", "rad/s"]
    )
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    mu = b.premise("mu", sinc(th_l), text="sin(theta_l)/theta_l")
    b.drift(
        [
            w_m + a[0] * d,
            p["k_Jm"] * (th_l - th_m) - p["G_Jm"] * w_m + p["ktau_Jm"] * (u + fa) + a[1] * d,
            w_l + a[2] * d,
            -p["k_Jl"] * (th_l - th_m) - p["mgh_Jl"] * mu * th_l + a[3] * d,  # sin(th_l) = mu * th_l
        ]
    )
    b.diffusion(
        [
            w["W12"] * w_m,
            w["W23"] * th_l + w["W21"] * th_m + w["W22"] * w_m,
            w["W34"] * w_l,
            w["W43"] * th_l + w["W41"] * th_m + w["Ws"] * mu * th_l,
        ]
    )
    b.outputs([th_m + fs, w_m, th_l], names=["theta_m", "w_m", "theta_l"])
    b.region(
        theta_l=(-2 * ca.pi, 2 * ca.pi), theta_m=(-2 * ca.pi, 2 * ca.pi), w_m=(-5.0, 5.0), w_l=(-5.0, 5.0)
    )
    b.reference(u=[2.0])
    b.initial_state([0.1, 0.05, 0.02, 0.03])
    # Section 6.1's parameters were gamma = 2, gamma1 = 0.01, sigma = 0.2, rho0 = eps = 1e-5 (delta not given: = eps).
    # The defaults are `fte tune`'s (rounded to 3 digits): `fte tune manipulator --trials 60 --seed 1` chose its
    # trial 58 (the bound's weight 0.475), and its decay rate raised from 0.857 to 0.9 x the default rate at those
    # knobs (a one-knob step, by hand) makes it better than Section 6.1's on every fault metric (docs/tune.md)
    b.design_defaults(gamma=2.49, gamma1=0.0176, sigma=0.151, delta=1e-5, epsilon=8.4e-6, alpha=1.48, kappa=1.73e4,
                      bound_weight=0.475)  # fmt: skip
    b.parameters(**p, **{f"alpha_d{k + 1}": v for k, v in enumerate(a)}, **w)
    return b.build()


def scenario():
    """Section 6.1's experiment: 40 % loss of actuator effectiveness for 2.5 <= t < 5 s (``fa = -0.4 u``),
    first sensor stuck at its reading at t = 7 s for 7 <= t < 10 s, d uniform in [-0.1, 0.1] each step,
    x0 = [0.1, 0.05, 0.02, 0.03] plus Gaussian noise (std 0.005), T = 10 s, dt = 1 ms, 5 paths."""
    from ..sim import LossOfEffectiveness, Scenario, Stuck, UniformNoise

    return Scenario(
        name="manipulator",
        T=10.0,
        dt=1e-3,
        faults=(LossOfEffectiveness("fa", loss=0.4, start=2.5, stop=5.0), Stuck("fs", start=7.0, stop=10.0)),
        unknown_input=UniformNoise(0.1),
        x0=(0.1, 0.05, 0.02, 0.03),
        x0_noise=0.005,
        paths=5,
    )
