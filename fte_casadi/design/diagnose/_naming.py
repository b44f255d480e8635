"""The cause of a refusal, named where one is found: decided on the LMIs, each claim run rather than guessed.

Behind an infeasible (45) or (46) a diagnosis looks, in order, for the plant's diffusion
(:func:`~._diffusion.tolerance`: the fraction of it the design tolerates, and whether the whole design certifies
with the diffusion scaled to that fraction), a fault the outputs tell apart only weakly
(:func:`~._separability.blocking`), and the cover's vertices (:func:`~._other_cover.other_cover`); before them, the
plant's time unit (:func:`~._time_unit.other_unit`: the same plant in another unit certifies). What it finds
is a record with a ``render()``, carried by the refusal (:attr:`~fte_casadi.errors.Refusal.found`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

from ..._text import shorten
from ...errors import InfeasibleDesignError
from . import _diffusion as diffusion
from . import _necessary as necessary
from . import _separability as separability
from ._other_cover import other_cover
from ._parameters import Attempt, Trial, try_design
from ._time_unit import other_unit

__all__ = ["name_cause", "blocking_diffusion", "weak_faults", "Diffusion", "DECIDING_SOLVER"]

#: the solver the causes of a refusal are decided with (:func:`name_cause`, and ``explore``'s cause): the
#: interior-point solver (and phase 1 in numpy where it fails), whichever solver the design asked for; SCS's
#: first-order answers near the boundary decide less
DECIDING_SOLVER = "CLARABEL"


@dataclass(frozen=True)
class Diffusion:
    """The cause a refusal names: the plant's diffusion (``tolerance``: the fraction of it the design tolerates)
    at the parameters ``at``; ``scaled``: whether the whole design is certified with the diffusion scaled to the
    fraction found feasible (None: not run), and ``why`` not, where it is not; ``plant``: the rules that are not
    mean-square stabilisable or detectable with the plant's diffusion (:func:`~._necessary.limits`: no design of
    any structure can do better; empty where every rule is both, or it was not decided)."""

    tolerance: diffusion.Tolerance
    at: Mapping[str, float]
    scaled: bool | None = None
    why: str = ""
    plant: tuple[necessary.Limit, ...] = ()

    @property
    def the_plant(self) -> bool:
        """Is it the plant, not the method: does a necessary condition of any design fail at its diffusion?"""
        return bool(self.plant)

    def render(self) -> str:
        """The sentence a refusal carries (and ``explore``'s cause, where the scaled design is not run)."""
        where = ", ".join(f"{k} = {v:g}" for k, v in self.at.items())
        text = f"{self.tolerance.text()} at {where}"
        if self.plant:
            text += (f". It is the plant, not the method: {necessary.describe(list(self.plant))} (a necessary "
                     "condition for any design; docs/method.md, \"What no observer can do\")")  # fmt: skip
        s = self.tolerance.feasible
        if self.scaled is None:
            return text
        if self.scaled:
            return (f"{text}. With the diffusion scaled by {s:.3g} the whole design is certified (checked): if the "
                    "plant's noise is smaller than written, write it as it is; otherwise this method cannot certify an "
                    "observer for it at the parameters tried")  # fmt: skip
        return (
            f"{text}. Even with the diffusion scaled by {s:.3g} the whole design is not certified: {self.why}"
        )


def past_step3(refused: list[Trial]) -> dict:
    """The change of the first value tried that step 3 passed (refused by (46)), {} where none did."""
    return next((t.change for t in refused if t.lmi == "46"), {})


def blocking_diffusion(aug, T, params: dict, at: Mapping[str, float]) -> Diffusion | None:
    """The plant's diffusion as the cause of a refusal at ``params`` (decided with :data:`DECIDING_SOLVER`), or
    None where the design is infeasible without it too, or the plant has none."""
    tol = diffusion.tolerance(aug, T, params, DECIDING_SOLVER)
    if tol is None or not tol.blocks:
        return None
    return Diffusion(tol, dict(at), plant=tuple(necessary.limits(aug, DECIDING_SOLVER)))


def weak_faults(ts, params: dict, at: Mapping[str, float]) -> separability.Faults | None:
    """The faults the outputs tell apart only weakly, without each of which (45)-(46) are feasible at ``params``
    (decided with :data:`DECIDING_SOLVER`), or None."""
    found = separability.blocking(ts, params, DECIDING_SOLVER)
    return separability.Faults(tuple(found), dict(at)) if found else None


def name_cause(attempt: Attempt, err: InfeasibleDesignError, ts, options, st, params: dict, refused: list[Trial],
               lmi: str) -> InfeasibleDesignError:  # fmt: skip
    """``err`` with its cause named (:attr:`~fte_casadi.errors.Refusal.found`), where one is found: first the plant's
    time unit, where its rates are far from 1 per it and the same plant in another unit certifies
    (:func:`~._time_unit.other_unit`); else, at the
    parameters tried where (45) held (else the given ones): the diffusion (the fraction of it the design
    tolerates, and whether the whole design certifies with the diffusion scaled to that fraction, run, not
    guessed), else, where (46) fails, a fault the outputs tell apart only weakly, else the cover's vertices where
    another cover gives a certified design. ``lmi``: the LMI that failed at the given parameters."""
    unit = other_unit(attempt, ts, options)
    if unit is not None:
        return InfeasibleDesignError(dataclasses.replace(err.refusal, found=unit))
    at = past_step3(refused)
    p = dict(params, **at)
    where = {k: p[k] for k in ("sigma", "gamma", "gamma1")}
    found = blocking_diffusion(st.aug, st.T, p, where)
    if found is not None and found.tolerance.feasible > 0:
        why: list[Trial] = []
        d = try_design(attempt, diffusion.scaled_model(ts, found.tolerance.feasible), options, why, **at)
        found = dataclasses.replace(found, scaled=d is not None,
                                    why=shorten(why[0].message, 300) if why else "not certified")  # fmt: skip
    elif found is None:
        if (at or lmi == "46") and not st.r5doc:
            found = weak_faults(ts, p, where)
        if found is None:
            found = other_cover(attempt, ts, options)
    if found is None:
        return err
    return InfeasibleDesignError(dataclasses.replace(err.refusal, found=found))
