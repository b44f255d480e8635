"""The plant's time unit as the cause of a refusal: the same plant, its time counted in another unit, certifies.

A change of time unit (``t = c s``) multiplies the drift by ``c`` and the diffusion by ``sqrt(c)``: the same plant,
the same physics. The design is not invariant under it: the augmented state carries the faults' rates ``fdot`` in
fault units per time unit (its block ``f' = fdot`` stays the identity), so the same Lyapunov function has its
``fdot`` block scaled by up to ``c^2``, another cond(Pbar) under the bound kappa and another feasible set of (46);
step 5's objective weighs the observer's gains against the sliding term per unit of time (docs/design.md, "Units and the plant's own time"). A plant written in seconds whose rates are 3e-5 to 1.2e-3
per second (a building's temperatures, ``tests/plant_house.py``) then asks sigma below 5e-9, (46) fails at every
sigma tried, and it is refused, while the same plant in hours certifies at the defaults.

:func:`other_unit` runs that check where the plant's fastest rate lies outside ``[1 / RATE_FAR, RATE_FAR]`` per its
time unit and sigma is the tool's to choose: the whole design of the plant in the named unit of :data:`UNITS` that
brings its fastest rate nearest to 1, with the sample time, the settling window and any decay rate given
converted. Where it certifies, the refusal says so, with the numbers, as its cause.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from ._parameters import Attempt, Trial, try_design

__all__ = ["TimeUnit", "other_unit", "time_scaled_model", "unit_for", "fastest_rate"]

#: a plant whose fastest rate is beyond this factor from 1 per its time unit (either side) is checked in another
RATE_FAR = 1e2
#: the units tried, as multiples ``c`` of the plant's time unit, and their names where that unit is the second
UNITS = (
    (1e-6, "microsecond"),
    (1e-3, "millisecond"),
    (60.0, "minute"),
    (3600.0, "hour"),
    (86400.0, "day"),
)


def fastest_rate(ts) -> float:
    """The largest modulus of the eigenvalues of the rules' ``A_i``: the plant's fastest rate per its time unit."""
    return max(float(np.max(np.abs(np.linalg.eigvals(np.asarray(lm.A, float))))) for lm in ts.local_models)


def unit_for(ts) -> tuple[float, str] | None:
    """``(c, name)`` of the unit of :data:`UNITS` that brings the plant's fastest rate nearest to 1, where that rate
    lies beyond :data:`RATE_FAR` from 1; None where it does not (or the plant has no rate)."""
    r = fastest_rate(ts) if ts.plant.n else 0.0
    if not (r > 0 and math.isfinite(r)) or 1.0 / RATE_FAR <= r <= RATE_FAR:
        return None
    return min(UNITS, key=lambda u: abs(math.log10(r * u[0])))


def time_scaled_model(ts, c: float):
    """``ts`` with its time counted in units of ``c`` of its own: drift (and its offsets, inputs, faults, unknown
    inputs) times ``c``, diffusion times ``sqrt(c)`` (a Brownian increment over ``c`` of the old units is
    ``sqrt(c)`` times one over one), in the T-S model's rules and in its nonlinear plant."""
    q = math.sqrt(c)
    models = tuple(
        dataclasses.replace(
            lm,
            A=c * lm.A,
            B=c * lm.B,
            Bd=c * lm.Bd,
            Bf=c * lm.Bf,
            a=None if lm.a is None else c * lm.a,
            W=q * lm.W,
            G=None if lm.G is None else q * lm.G,
            Gf=None if lm.Gf is None else q * lm.Gf,
            M=None if lm.M is None else q * lm.M,
        )
        for lm in ts.local_models
    )
    p = ts.plant
    defaults = dict(p.design_defaults)
    if "alpha" in defaults:  # a decay rate, per time unit
        defaults["alpha"] = c * defaults["alpha"]
    plant = dataclasses.replace(p, drift_z=c * p.drift_z, diffusion_z=q * p.diffusion_z,
                                time_unit=f"{c:g} {p.time_unit}", design_defaults=defaults)  # fmt: skip
    return dataclasses.replace(ts, local_models=models, plant=plant)


def _scaled_options(options, c: float):
    """``options`` in the new unit: times divided by ``c``, rates multiplied by it."""
    change = {}
    for k in ("sample_time", "settle_window"):
        if getattr(options, k):
            change[k] = getattr(options, k) / c
    for k in ("alpha", "beta"):
        if getattr(options, k) is not None:
            change[k] = getattr(options, k) * c
    return options.replace(**change)


@dataclass(frozen=True)
class TimeUnit:
    """The cause a refusal names: the plant's time unit. Its fastest rate ``rate`` per ``unit``; in units of ``c``
    of it (``name``) the whole design certifies, at ``sigma``, its observer decaying at ``alpha`` per new unit."""

    rate: float
    unit: str
    c: float
    name: str
    sigma: float
    alpha: float | None

    def render(self) -> str:
        seconds = self.unit == "s"  # a unit of UNITS is named where the plant counts time in seconds
        per = self.name if seconds else f"{self.c:g} {self.unit}"
        decay = "" if self.alpha is None else f", its observer decaying at {self.alpha:.3g} per {per}"
        return (
            f"the plant's time unit is the cause: its fastest rate is {self.rate:.3g} per {self.unit}, far from 1, "
            "and the design is not invariant under the time unit (kappa bounds cond(Pbar) with the faults' rates in "
            f"fault units per time unit; docs/design.md). The same plant with its time in "
            f"{self.name + 's' if seconds else 'units of ' + per} ({self.c:g} {self.unit}: every drift term x "
            f"{self.c:g}, the diffusion x {math.sqrt(self.c):.4g}, the scenario's times and sample time / {self.c:g}) "
            f"certifies at the defaults (checked: sigma = {self.sigma:.3g}{decay}); write it so"
        )


def other_unit(attempt: Attempt, ts, options) -> TimeUnit | None:
    """The :class:`TimeUnit` cause of a refusal of ``ts`` at ``options``, where the plant's rates are far from 1 per
    its time unit, sigma is the tool's to choose, and the whole design (its parameter search included) of the plant
    in the unit of :func:`unit_for` certifies; None otherwise."""
    unit = unit_for(ts)
    if unit is None or options.sigma is not None or "sigma" in ts.plant.design_defaults:
        return None
    c, name = unit
    why: list[Trial] = []
    d = try_design(attempt, time_scaled_model(ts, c), _scaled_options(options, c), why, diagnose=True)
    if d is None:
        return None
    alpha = None if d.observer.alpha is None else float(d.observer.alpha)
    return TimeUnit(fastest_rate(ts), ts.plant.time_unit, c, name, float(d.params.sigma), alpha)
