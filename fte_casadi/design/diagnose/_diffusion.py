"""How much of a plant's diffusion a design tolerates: the number a refusal names when the diffusion blocks it.

The Brownian terms of the plant (``W x + G u + Gf f + M d2`` in every rule) enter LMIs (45) and (46) through
``X W^T`` and ``Wbar^T T^T Pbar T Wbar`` (and (29) through ``W^T P29 W`` and the same observer term). Scaled by
``s`` in ``[0, 1]`` (``s = 0``: the plant without diffusion, ``s = 1``: as written), the design's feasibility is
decided at each ``s`` the way the design decides it (step 3, then step 5's feasibility at ``alpha = 0`` by (46),
else by Theorem 1's (29), each with phase 1 in numpy where the conic solver fails), so the answer is a fact about
the LMIs. :func:`tolerance` bisects ``s``; a design that is also infeasible at ``s = 0`` is not blocked by its
diffusion, and then no fraction is named. ``routes=("46",)`` measures what (45)-(46) alone tolerate (the paper's
certificate; docs/design.md has both).

Where the diffusion blocks the design, :func:`~._necessary.limits` says whether any feedback could do better: a rule whose
local model is not mean-square stabilisable, or not mean-square detectable, with the diffusion scaled by s has no
linear controller at all, the observer-based one or any other, that makes it mean-square stable (docs/method.md,
"What no observer can do"): then it is the plant, not the method.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ...errors import FteError
from .._augment import Augmented
from ..core import _conditioned as conditioned
from ..core import _step5

__all__ = ["tolerance"]


@dataclasses.dataclass(frozen=True)
class Tolerance:
    """The largest diffusion scale found feasible (``feasible``) and the smallest found infeasible
    (``infeasible``), as fractions of the plant's; ``feasible = 0`` and ``infeasible = 0``: infeasible even
    without diffusion (the diffusion is not the cause)."""

    feasible: float
    infeasible: float
    lmi: str  # the LMI that decides at the infeasible end: "45", "46", or "29" (where (46) fails too)
    routes: tuple = ("46", "29")  # the step-5 LMIs tried

    @property
    def blocks(self) -> bool:
        """Is the diffusion the cause (feasible without it, infeasible with all of it)?"""
        return self.infeasible > 0

    def text(self) -> str:
        """The sentence a refusal carries."""
        if not self.blocks:
            return ""
        pct = 100.0 * self.feasible
        got = f"{pct:.2g} %" if self.feasible > 0 else "none"
        lmis = "(45) and (46), or (29)," if "29" in self.routes else "(45)-(46)"
        fails = "(46) and (29) fail" if self.lmi == "29" else f"({self.lmi}) fails"
        return (
            f"the plant's diffusion is the cause: the design tolerates {got} of it (LMIs {lmis} with every "
            f"diffusion term scaled by s are feasible at s = {self.feasible:.3g} and infeasible at s = "
            f"{self.infeasible:.3g}, where {fails}; at s = 0 they are feasible)"
        )


def scaled(aug: Augmented, s: float) -> Augmented:
    """``aug`` with every diffusion term (``Wbar``, ``Gbar``, ``Gfbar``, ``Mbar``) multiplied by ``s``."""
    return dataclasses.replace(
        aug,
        Wbar=tuple(s * W for W in aug.Wbar),
        Gbar=tuple(s * G for G in aug.Gbar),
        Gfbar=tuple(s * G for G in aug.Gfbar),
        Mbar=tuple(s * M for M in aug.Mbar),
    )


def scaled_model(ts, s: float):
    """The T-S model ``ts`` with every rule's diffusion (``W``, ``G``, ``Gf``, ``M``) multiplied by ``s``."""
    models = tuple(
        dataclasses.replace(lm, W=s * lm.W, G=s * lm.G, Gf=s * lm.Gf, M=s * lm.M) for lm in ts.local_models
    )
    return dataclasses.replace(ts, local_models=models)


def has_diffusion(aug: Augmented) -> bool:
    return any(np.any(M) for group in (aug.Wbar, aug.Gbar, aug.Gfbar, aug.Mbar) for M in group)


#: the step-5 LMIs a design tries, in order: (46), then Theorem 1's (29) where (46) fails
ROUTES = ("46", "29")


def feasible(
    aug: Augmented, T: np.ndarray, params: dict, solver: str, *, strict: bool = False, routes: tuple = ROUTES
) -> str | None:
    """None when steps 3 and 5 (at alpha = 0) are feasible for ``aug``, else the LMI that fails ("45", or the last
    of ``routes``: "46", "29"). A solver's numerical failure (where phase 1 in numpy did not decide either) counts as
    a failure, or, with ``strict``, gives "undecided": a claim that the LMIs are infeasible needs a decision, not a
    failure."""
    try:
        s3 = conditioned.step3(aug, params, solver)
    except conditioned.SolverFailedError:
        return "undecided" if strict else "45"
    except FteError:
        return "45"
    why = None
    for lmi in routes:
        try:
            prob = _step5._Step5(aug, params, s3.X, s3.K, T, solver, joint=lmi == "29")
            prob.first()
        except conditioned.SolverFailedError:
            why = "undecided" if strict else lmi
            continue
        except FteError:
            why = why if why == "undecided" else lmi
            continue
        if prob.points:
            return None
        why = why if why == "undecided" else lmi
    return why


def tolerance(
    aug: Augmented, T: np.ndarray, params: dict, solver: str, *, steps: int = 7, routes: tuple = ROUTES,
    top: float = 1.0,
) -> Tolerance | None:  # fmt: skip
    """The fraction of ``aug``'s diffusion for which the design's LMIs are feasible at ``params``, or None
    when the plant has no diffusion or the whole diffusion is feasible (up to ``top`` times it: a measurement may
    look above the plant's own diffusion).

    Bisection in ``log s`` between 1e-4 and ``top`` (``steps`` decisions after the ends), so the bracket is a
    factor ``(1e4 top) ** (1 / 2**steps)`` wide (7 steps, top 1: 7 %). ``routes``: the step-5 LMIs tried
    (:func:`feasible`)."""
    if not has_diffusion(aug):
        return None

    def decide(s: float) -> str | None:
        return feasible(scaled(aug, s), T, params, solver, routes=routes)

    at_top = decide(top)
    if at_top is None:
        return None
    if decide(0.0) is not None:
        return Tolerance(0.0, 0.0, at_top, routes)
    lo, hi, lmi = 1e-4, top, at_top
    failed_lo = decide(lo)
    if failed_lo is not None:
        return Tolerance(0.0, lo, failed_lo, routes)
    for _ in range(steps):
        mid = math.sqrt(lo * hi)
        why = decide(mid)
        if why is None:
            lo = mid
        else:
            hi, lmi = mid, why
    return Tolerance(lo, hi, lmi, routes)
