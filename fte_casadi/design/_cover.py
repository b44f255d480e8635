"""When the cover's vertices are the cause: the same premises covered another way, checked by a whole design.

The sector method blends local models at the vertices of a polytope enclosing the premises' image
(:mod:`fte_casadi.ts._cover`); LMIs (45)-(46) must hold at every vertex, also at the ones no state of the
region reaches (a box's corners where premises of shared states are at independent extremes, a simplex's
corners around a curve). Such a vertex can carry behaviour the plant does not have (an unstable mode its
inputs barely reach) and block the design. :func:`other_cover` names how many rules' vertices no state
reaches and runs the whole design with each other cover (``fte design --vertices``): it is named only
where that design is certified.
"""

from __future__ import annotations

import numpy as np

from ..errors import FteError
from ..ts import VERTEX_CHOICES, structure
from ._limits import NEAR_IMAGE
from ._search import try_design

__all__ = ["other_cover"]

#: set while another cover is being designed: its own refusal does not try the covers again
_ACTIVE: list = []
#: another cover is tried only with at most this many rules, and at most this many times the cover's own: the
#: quadrotor's 48 rules became 1024 in a box, whose design held 7.3 GB after 17 minutes
MAX_OTHER_RULES = 128
MAX_OTHER_FACTOR = 4


def _certified(attempt, ts, options):
    """The whole design of ``ts`` with ``options`` (its parameter search included, its cover not questioned
    again), or None when it is refused or not certified."""
    _ACTIVE.append(True)
    try:
        return try_design(attempt, ts, options, diagnose=True)
    finally:
        _ACTIVE.pop()


def other_cover(attempt, ts, options) -> str:
    """The sentence a refusal carries when another cover of ``ts``'s premises gives a certified design (run
    with ``options``, its parameter search included), "" when ``ts`` has no vertex a state does not reach, no other cover, or
    none that certifies."""
    distances = ts.rule_distances
    if _ACTIVE or ts.vertices is None or distances is None or not np.any(np.asarray(distances) > NEAR_IMAGE):
        return ""
    far = np.asarray(distances, dtype=float)
    unreached = int(np.sum(far > NEAR_IMAGE))
    for choice in (v for v in VERTEX_CHOICES if v != ts.vertices):
        try:
            other = structure(ts.plant, vertices=choice)
        except FteError:
            continue
        if other.r == ts.r and all(
            np.allclose(a.A, b.A) for a, b in zip(other.local_models, ts.local_models)
        ):
            continue  # the same cover under another name (a single premise: the sector either way)
        if other.r > max(MAX_OTHER_RULES, ts.r) or other.r > MAX_OTHER_FACTOR * ts.r:
            continue  # a design too large to run as a diagnosis
        d = _certified(attempt, other, options)
        if d is not None:
            return (
                f"the cover's vertices are the cause: {unreached} of the {ts.r} rules ({ts.vertices} cover) have "
                f"vertices no state of the region reaches (up to {far.max():.2g} of the image's extent away), and "
                f"(45)-(46) must hold there too; covered with --vertices {choice} ({other.r} rules) the whole design "
                "is certified (checked): design with `fte design PLANT --vertices "
                f"{choice}{options.flags()}` (or derive(plant, vertices='{choice}'))"
            )
    return ""
