"""T-S derivation: sector nonlinearity, local linearisation, memberships, fidelity."""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import DerivationError, ParameterError
from ..model import Plant
from ._auto import premise_form
from ._auto_checks import check_exact
from ._cover import VERTEX_CHOICES as VERTEX_CHOICES
from ._cover import group_notes
from ._fidelity import fidelity as fidelity
from ._linearise import linearised_local_models
from ._memberships import scheduling_from_measurements as scheduling_from_measurements
from ._model import Fidelity as Fidelity
from ._model import LocalModel as LocalModel
from ._model import Premise as Premise
from ._model import TSModel as TSModel
from ._model import as_model as as_model
from ._reach import reach_notes
from ._sector import sector_local_models


def _finite_models(plant: Plant, models) -> None:
    """Refuse local models with an infinite or NaN entry: a coefficient of the plant is not finite."""
    for i, lm in enumerate(models):
        for key in ("A", "B", "Bd", "Bf", "W", "a", "G", "Gf", "M"):
            M = np.asarray(lm[key], dtype=float)
            bad = np.argwhere(~np.isfinite(M))
            if bad.size:
                at = ", ".join(str(int(v) + 1) for v in bad[0])
                raise DerivationError(
                    f"plant {plant.name}: rule {i + 1}'s local model has {key}[{at}] = {M[tuple(bad[0])]}: a coefficient "
                    "of the plant's equations is infinite or NaN (a parameter set to inf or nan, or a division by zero "
                    "at the rule's premise values); fix the plant's parameters"
                )


def structure(plant: Plant, *, seed: int = 0, vertices: str | None = None) -> TSModel:
    """The T-S model of ``plant`` without its fidelity check (``fidelity`` holds NaN): premises, local
    models and memberships, as :func:`derive` finds them. Rebuilding a design's scheduling map from its
    plant needs this much, in milliseconds to a few seconds, not the fidelity integration."""
    if vertices is not None and vertices not in VERTEX_CHOICES:
        raise ParameterError(f"vertices must be one of {', '.join(VERTEX_CHOICES)}; got {vertices!r}")
    kind = plant.method  # "sector" or "linearisation"
    auto = plant.method == "sector" and plant.z.numel() == 0  # no premise declared: find them
    notes: tuple[str, ...] = ()
    groups = ()
    if auto:
        vertices = vertices or "grouped"
        form = premise_form(plant, seed=seed)
        premises, models, premise_fn, membership_fn, groups = sector_local_models(
            form.plant, form.bounds, vertices, seed
        )
        kind = "sector_auto" if premises else "linear"
        notes = form.notes + group_notes(premises, groups)
    elif plant.method == "sector":
        vertices = vertices or "box"
        premises, models, premise_fn, membership_fn, groups = sector_local_models(plant, None, vertices, seed)
        notes = group_notes(premises, groups) if len(groups) < len(premises) else ()
    else:
        vertices = None  # operating points: no premise to cover
        premises, models, premise_fn, membership_fn = linearised_local_models(plant)
    _finite_models(plant, models)
    ts = TSModel(
        plant,
        kind,
        premises,
        models,
        plant.C,
        plant.Df,
        premise_fn,
        membership_fn,
        Fidelity(np.nan, 0, np.nan, np.nan, np.nan, np.nan, 0, 0.0),
        notes,
        groups,
        vertices,
    )
    unreached = reach_notes(ts)  # a mode at the origin no feedback of the model reaches: no design exists
    return dataclasses.replace(ts, notes=ts.notes + unreached) if unreached else ts


def derive(
    plant: Plant, *, fidelity_samples: int = 20_000, seed: int = 0, vertices: str | None = None
) -> TSModel:
    """Derive the T-S fuzzy model of ``plant`` and check its fidelity.

    Sector nonlinearity when the plant declares premises, or when it declares neither premises nor
    operating points: the premises are then found in its plain equations (:mod:`._auto`), the
    model is checked to equal them to round-off (:func:`._auto_checks.check_exact`), and a plant
    without nonlinear term gets one rule. Local linearisation when it declares operating points.

    Examples
    --------
    >>> from fte_casadi.plants import manipulator
    >>> ts = derive(manipulator())
    >>> ts.r, round(ts.premises[0].min, 4)
    (2, -0.2172)
    """
    tmp = structure(plant, seed=seed, vertices=vertices)
    fid = fidelity(tmp, samples=fidelity_samples, seed=seed)
    ts = dataclasses.replace(tmp, fidelity=fid)
    if tmp.kind in ("sector_auto", "linear") and plant.method == "sector" and plant.z.numel() == 0:
        check_exact(ts, seed=seed)  # the proof: exact to round-off, or refused with the row and the point
    return ts


__all__ = [
    "derive",
    "structure",
    "TSModel",
    "LocalModel",
    "Premise",
    "Fidelity",
    "fidelity",
    "scheduling_from_measurements",
    "VERTEX_CHOICES",
]
