"""T-S models by the sector-nonlinearity method (exact on the region)."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import DerivationError
from ..model import Plant
from ._cover import cover_premises, memberships_of, rule_vertices_of
from ._model import LocalModel, Premise
from ._premise_bounds import premise_bounds

__all__ = ["sector_local_models"]


def _coefficients(plant: Plant):
    """Symbolic coefficient matrices of the drift/diffusion as functions of the premises z."""
    x, u, d, f, d2 = plant.x, plant.u, plant.d, plant.f, plant.d2
    fz, gz = plant.drift_z, plant.diffusion_z
    zero_v = ca.vertcat(x, u, d, f)
    zero_w = ca.vertcat(x, u, f, d2)
    a = ca.substitute(fz, zero_v, ca.DM.zeros(zero_v.numel()))
    c = ca.substitute(gz, zero_w, ca.DM.zeros(zero_w.numel()))
    mats = {
        "A": ca.jacobian(fz, x),
        "B": ca.jacobian(fz, u),
        "Bd": ca.jacobian(fz, d) if d.numel() else ca.SX(plant.n, 0),
        "Bf": ca.jacobian(fz, f),
        "W": ca.jacobian(gz, x),
        "G": ca.jacobian(gz, u),
        "Gf": ca.jacobian(gz, f),
        "M": ca.jacobian(gz, d2) if d2.numel() else ca.SX(plant.n, 0),
        "a": a,
    }
    return mats, c


def sector_local_models(plant: Plant, bounds=None, vertices: str = "box", seed: int = 0):
    """Local models at the vertices of the polytopes covering the premises, memberships, premise Function,
    and the groups (:mod:`._cover`): ``(premises, models, premise_fn, membership_fn, groups)``.

    ``bounds``: per premise ``(min, max, states, gap)`` when already known (the automatic method
    finds them to orient its premises); otherwise they come from the global bound search.
    ``vertices``: how the premises are covered (:data:`~fte_casadi.ts._cover.VERTEX_CHOICES`); ``box``
    is each premise on its own bounds, 2^q rules.
    """
    mats, c = _coefficients(plant)
    z = plant.z
    q = z.numel()
    if np.any(np.array(ca.Function("c", [z], [c])(np.zeros(q)))) or ca.depends_on(c, z):
        raise DerivationError(
            "the diffusion has a term that is not proportional to x, u, f or d2 (additive noise): the paper's model has none"
        )
    for key, M in mats.items():
        for k in range(q):
            dz = ca.jacobian(M.reshape((-1, 1)) if M.numel() else M, z[k]) if M.numel() else M
            if M.numel() and ca.depends_on(dz, z[k]):
                raise DerivationError(
                    f"the coefficient {key} depends nonlinearly on premise {plant.z_names[k]!r}; the sector "
                    "method needs it affine in each premise: declare the product or power as a premise of its own"
                )
    premises = []
    mins, maxs = [], []
    for k in range(q):
        mn, mx, idx, gap = (
            bounds[k]
            if bounds is not None
            else premise_bounds(
                plant.z_names[k],
                plant.z_exprs[k],
                plant.x,
                plant.region_lo,
                plant.region_hi,
                plant.state_names,
            )
        )
        mins.append(mn)
        maxs.append(mx)
        premises.append(Premise(plant.z_names[k], plant.z_texts[k], float(mn), float(mx), idx, float(gap)))
    fn = ca.Function("coeffs", [z], [mats[k] for k in mats])
    groups = cover_premises(plant.z_exprs, plant.x, plant.region_lo, plant.region_hi, mins, maxs,
                            [p.states for p in premises], vertices, seed)  # fmt: skip
    models = []
    for zi in rule_vertices_of(groups, q):
        vals = dict(zip(mats, (np.array(v, dtype=float) for v in fn(zi))))
        models.append(
            LocalModel(
                A=vals["A"],
                B=vals["B"],
                Bd=vals["Bd"].reshape(plant.n, -1),
                Bf=vals["Bf"],
                W=vals["W"],
                a=vals["a"].ravel(),
                G=vals["G"],
                Gf=vals["Gf"],
                M=vals["M"].reshape(plant.n, -1),
            )
        )
    premise_fn = ca.Function("premises", [plant.x], [plant.z_exprs], ["x"], ["premises"])
    return tuple(premises), tuple(models), premise_fn, memberships_of(groups, q), groups
