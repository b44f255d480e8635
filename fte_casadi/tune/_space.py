"""The search space of ``fte tune``: the design's knobs, on scales taken from the plant itself.

Every positive knob is searched on a log scale, around the base design's own value (the plant's
defaults, or the values the tool chose, or those of the DESIGN.json tuned from), so that the
ranges follow the plant's units:

============== ============================================================ =========================
knob           range                                                        base value
============== ============================================================ =========================
sigma          [sigma0 / 10, min(10 sigma0, 0.98 sigma_sup)]; sigma_sup the  sigma0
               largest sigma (45) allows for any gamma (design.diagnose)
gamma          [gamma0 / 3, 10 gamma0]                                      gamma0
gamma1_ratio   gamma1 / gamma in [r0 / 30, min(0.95, 30 r0)]                r0 = gamma1_0 / gamma0
alpha_scale    the observer decay rate as a fraction of the one the design  1, or the base's own
               takes by default (its largest feasible, capped for the
               sample time): [0.05, 1], widened to hold the base's
kappa          the bound on cond(Pbar) (and cond(X')): [1e2, 1e6]           the base's (1e4, KAPPA)
epsilon        the sliding gain's margin (gain delta + epsilon):            epsilon0
               [epsilon0 / 10, 1000 epsilon0]
boundary layer use_boundary_layer in {no, yes}; phi = boundary_layer_rel    the base's (no)
               x ||N|| x the base run's RMS output error, with
               boundary_layer_rel in [0.01, 100]
bound weight   use_bound_weight in {no, yes}; bound_weight in [0.01, 100]:   the base's (no; 1)
               the fault-error bound's weight in step 5's objective
               (design.bound_objective)
============== ============================================================ =========================
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["Space", "space_for"]


@dataclass(frozen=True)
class Space:
    """Ranges (low, high) of the float knobs, all log scale, and the base design's knobs."""

    ranges: dict
    base: dict

    def local_steps(self, budget: int) -> list[dict]:
        """Knobs one step from the base design, one knob at a time: each float knob (the boundary
        layer's width aside) multiplied and divided by :data:`LOCAL_FACTOR` (clipped to its range),
        then the boundary layer switched. Asked first after the base, when the budget leaves at least
        :data:`LOCAL_SHARE` x their number for the sampler; none otherwise.

        The chosen design is compared with the base, and a design better than the base on every metric
        lies, if anywhere, near it (the base is the method's own choice, good on most metrics): a random
        start over ranges spanning factors of 30 to 1000 rarely lands there in a few dozen trials, these
        steps do, and they give the sampler each knob's local effect."""
        steps = []
        for k, (lo, hi) in self.ranges.items():
            if k in ("boundary_layer_rel", "bound_weight"):
                continue
            for f in (LOCAL_FACTOR, 1 / LOCAL_FACTOR):
                v = min(max(self.base[k] * f, lo), hi)
                if abs(v / self.base[k] - 1) > 1e-9:
                    steps.append(self.base | {k: v})
        steps.append(self.base | {"use_boundary_layer": not self.base["use_boundary_layer"]})
        steps.append(self.base | {"use_bound_weight": not self.base["use_bound_weight"]})
        return steps if budget >= LOCAL_SHARE * len(steps) else []

    def suggest(self, trial) -> dict:
        """The knobs of an optuna trial (the same names and order for every trial)."""
        out = {k: trial.suggest_float(k, lo, hi, log=True) for k, (lo, hi) in self.ranges.items()}
        out["use_boundary_layer"] = trial.suggest_categorical("use_boundary_layer", [False, True])
        out["use_bound_weight"] = trial.suggest_categorical("use_bound_weight", [False, True])
        return out


#: the factor of :meth:`Space.local_steps`
LOCAL_FACTOR = 2.0
#: local steps are taken when the trials after the base are at least this many times their number
LOCAL_SHARE = 3


def _around(v: float, lo: float, hi: float) -> tuple[float, float]:
    """``(lo, hi)`` widened to hold ``v``."""
    return (min(lo, v), max(hi, v))


def space_for(base_design, sigma_sup: float | None, alpha_scale: float = 1.0,
              boundary_layer_rel: float | None = None) -> Space:  # fmt: skip
    """The space around ``base_design`` (see the module docstring).

    ``alpha_scale`` and ``boundary_layer_rel`` are the base design's own values of those knobs when
    it has them (a design whose alpha or boundary layer came from an earlier tune, recorded in the
    plant's defaults): its alpha over the rate the design takes by default at its other knobs, and its
    boundary layer over ``||N||`` x the base run's RMS output error. The ranges are widened to hold them.
    The base's bound weight is its ``params.bound_weight`` (off when it has none).
    """
    from ..design import KAPPA

    p = base_design.params
    g0, s0, e0 = float(p.gamma), float(p.sigma), float(p.epsilon)
    r0 = float(p.gamma1) / g0
    kappa0 = float(KAPPA if p.kappa is None else p.kappa)
    w0 = p.bound_weight
    s_hi = 10 * s0 if not sigma_sup else min(10 * s0, 0.98 * sigma_sup)
    ranges = {
        "gamma": _around(g0, g0 / 3, 10 * g0),
        "gamma1_ratio": _around(r0, r0 / 30, min(0.95, 30 * r0)),
        "sigma": _around(s0, s0 / 10, max(s_hi, s0)),
        "alpha_scale": _around(alpha_scale, 0.05, 1.0),
        "kappa": _around(kappa0, 1e2, 1e6),
        "epsilon": _around(e0, e0 / 10, 1000 * e0),
        "boundary_layer_rel": _around(boundary_layer_rel or 1.0, 0.01, 100.0),
        "bound_weight": _around(w0 or 1.0, 0.01, 100.0),
    }
    for k, (lo, hi) in ranges.items():
        if not (math.isfinite(lo) and math.isfinite(hi) and 0 < lo <= hi):
            raise ValueError(f"search range of {k} is not a positive interval: ({lo}, {hi})")
    base = {"gamma": g0, "gamma1_ratio": r0, "sigma": s0, "alpha_scale": float(alpha_scale), "kappa": kappa0,
            "epsilon": e0, "boundary_layer_rel": float(boundary_layer_rel or 1.0),
            "use_boundary_layer": boundary_layer_rel is not None, "bound_weight": float(w0 or 1.0),
            "use_bound_weight": bool(w0)}  # fmt: skip
    return Space(ranges, base)
