"""When the cover's vertices are the cause: the same premises covered another way, checked by a whole design.

The sector method blends local models at the vertices of a polytope enclosing the premises' image
(:mod:`fte_casadi.ts._cover`); LMIs (45)-(46) must hold at every vertex, also at the ones no state of the
region reaches (a box's corners where premises of shared states are at independent extremes, a simplex's
corners around a curve). Such a vertex can carry behaviour the plant does not have (an unstable mode its
inputs barely reach) and block the design. :func:`other_cover` names how many rules' vertices no state
reaches and runs the whole design with each other cover (``fte design --vertices``): it is named only
where that design is certified, as the record :class:`OtherCover`.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...errors import FteError
from ...ts import VERTEX_CHOICES, structure
from .._limits import NEAR_IMAGE
from ._parameters import try_design

__all__ = ["other_cover", "OtherCover"]

#: set while another cover is being designed: its own refusal does not try the covers again
_ACTIVE: list = []
#: another cover is tried only with at most this many rules, and at most this many times the cover's own: the
#: quadrotor's 48 rules became 1024 in a box, whose design held 7.3 GB after 17 minutes
MAX_OTHER_RULES = 128
MAX_OTHER_FACTOR = 4


@dataclass(frozen=True)
class OtherCover:
    """The cause a refusal names: ``unreached`` of the ``rules`` rules of the ``vertices`` cover have vertices no
    state of the region reaches (up to ``farthest`` of the image's extent away), and covered with ``choice``
    (``choice_rules`` rules) the whole design is certified."""

    unreached: int
    rules: int
    vertices: str
    farthest: float
    choice: str
    choice_rules: int
    #: the options the user gave, as ``fte design`` flags (the advice was checked with them)
    flags: str = ""

    def render(self) -> str:
        """The sentence a refusal carries."""
        return (
            f"the cover's vertices are the cause: {self.unreached} of the {self.rules} rules ({self.vertices} cover) "
            f"have vertices no state of the region reaches (up to {self.farthest:.2g} of the image's extent away), "
            f"and (45)-(46) must hold there too; covered with --vertices {self.choice} ({self.choice_rules} rules) the "
            f"whole design is certified (checked): design with `fte design PLANT --vertices {self.choice}{self.flags}` (or "
            f"derive(plant, vertices='{self.choice}'))"
        )


def _certified(attempt, ts, options):
    """The whole design of ``ts`` with ``options`` (its parameter search included, its cover not questioned
    again), or None when it is refused or not certified."""
    _ACTIVE.append(True)
    try:
        return try_design(attempt, ts, options, diagnose=True)
    finally:
        _ACTIVE.pop()


def other_cover(attempt, ts, options) -> OtherCover | None:
    """The cause a refusal carries when another cover of ``ts``'s premises gives a certified design (run with
    ``options``, its parameter search included), None when ``ts`` has no vertex a state does not reach, no other
    cover, or none that certifies."""
    distances = ts.rule_distances
    if _ACTIVE or ts.vertices is None or distances is None or not np.any(np.asarray(distances) > NEAR_IMAGE):
        return None
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
        if _certified(attempt, other, options) is not None:
            return OtherCover(
                unreached, ts.r, ts.vertices, float(far.max()), choice, other.r, options.flags()
            )
    return None
