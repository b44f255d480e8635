"""Which fault blocks a design when the outputs tell it apart only weakly: the fault a refusal names, with numbers.

A fault is a state of (8) that the observer recovers from the outputs. Assumption (2) refuses a fault the
outputs cannot tell apart from the unknown inputs and the other faults at all (its rank test); one they tell
apart only weakly passes that test and can leave LMI (46) infeasible at every condition number the design
allows (two actuators that act almost alike, e.g. two fans on one block). :func:`blocking` leaves each
fault out of ``Bf``, ``Gf`` and ``Df`` in turn and decides the design's feasibility the way the design does
(:func:`~._diffusion.feasible`: step 3, then step 5 at alpha = 0, phase 1 in numpy where the conic solver
fails), so a fault is named only where (45)-(46) are feasible without it: a fact about the LMIs, with the
smallest singular value of assumption (2)'s column-normalised test with and without the fault
(:func:`~.._limits.separation`) as the measure of how weakly it is told apart.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from .._augment import augment
from .._limits import WEAK_SEPARATION, separation
from .._uio import uio_gain
from ._diffusion import feasible

__all__ = ["blocking", "Faults"]


@dataclass(frozen=True)
class Blocking:
    """Fault ``name`` (column ``k``): (45)-(46) are feasible without it; the separation of assumption (2)'s
    test with it (``with_it``, at rule ``rule``) and without it (``without``, the smallest over the rules)."""

    k: int
    name: str
    with_it: float
    without: float
    rule: int


@dataclass(frozen=True)
class Faults:
    """The cause a refusal names: the faults :func:`blocking` found (one or several), without each of which
    (45)-(46) are feasible at the parameters ``at`` (``{"sigma": ..., "gamma": ...}``)."""

    found: tuple[Blocking, ...]
    at: Mapping[str, float]

    def render(self) -> str:
        """The sentence a refusal carries."""
        b, found = self.found[0], self.found
        where = ", ".join(f"{k} = {v:g}" for k, v in self.at.items())
        test = (f"the smallest singular value of assumption (2)'s column-normalised test [[A_i, Bf_i, Bd_i], [C, Df, 0]] "
                f"is {b.with_it:.2g} at rule {b.rule + 1}")  # fmt: skip
        if len(found) == 1:
            return (
                f"fault {b.name!r} is the cause: the outputs tell it apart from the unknown inputs and the other faults "
                f"only weakly ({test}, {b.without:.2g} without it), and without it LMIs (45)-(46) are feasible at "
                f"{where} (checked); model only faults the outputs can tell apart, or measure what separates it"
            )
        names = ", ".join(repr(f.name) for f in found)
        without = ", ".join(f"{f.without:.2g} without {f.name!r}" for f in found)
        return (
            f"the faults {names} are the cause: the outputs tell them apart only weakly ({test}; {without}), and "
            f"without any one of them LMIs (45)-(46) are feasible at {where} (checked); where they act alike, model "
            "them as one fault, or measure what separates them"
        )


def _drop(models, k: int):
    keep = lambda M: None if M is None else np.delete(np.asarray(M), k, axis=1)  # noqa: E731
    return [dataclasses.replace(lm, Bf=keep(lm.Bf), Gf=keep(lm.Gf)) for lm in models]


def _separation(models, C, Df) -> tuple[float, int]:
    """The smallest separation of assumption (2)'s test over the rules, and the rule."""
    vals = [
        separation(
            lm.A, np.hstack([lm.Bf, lm.Bd]), C, np.hstack([Df, np.zeros((C.shape[0], lm.Bd.shape[1]))])
        )
        for lm in models
    ]
    i = int(np.argmin(vals))
    return float(vals[i]), i


def blocking(ts, params: dict, solver: str) -> list[Blocking]:
    """The faults of ``ts`` without which the design's LMIs are feasible at ``params`` (each decided by
    :func:`~._diffusion.feasible`: (45), then (46) or (29)); empty with fewer than two faults (without its only fault there is no
    observer to design), when the LMIs are feasible with every fault (the refusal has another cause), when
    the outputs tell the faults apart well (separation >= :data:`~.._limits.WEAK_SEPARATION`) or when no
    single fault is the cause."""
    names = list(ts.plant.fault_names)
    models, C, Df = list(ts.local_models), np.asarray(ts.C, float), np.asarray(ts.Df, float)
    if Df.shape[1] < 2:
        return []
    whole = augment(models, C, Df)
    if feasible(whole, uio_gain(whole)[1], params, solver, strict=True) not in ("45", "46", "29"):
        return []  # feasible with every fault (what failed is not (45)-(46) at alpha = 0, e.g. the sample time),
        # or not decided: no claim
    with_it, rule = _separation(models, C, Df)
    if with_it >= WEAK_SEPARATION:
        return []  # the outputs do tell the faults apart: leaving one out may help, but not for this reason
    out = []
    for k in range(Df.shape[1]):
        mk, Dk = _drop(models, k), np.delete(Df, k, axis=1)
        aug = augment(mk, C, Dk)
        _, T = uio_gain(aug)
        if feasible(aug, T, params, solver) is None:
            out.append(Blocking(k, names[k], with_it, _separation(mk, C, Dk)[0], rule))
    return out
