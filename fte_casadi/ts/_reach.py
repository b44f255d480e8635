"""What the model's inputs reach where the sector model is built: modes no feedback of the model can move.

A design certifies, through LMI (45), that ``A(h) + B(h) K(h)`` is stable for every blend ``h`` of the rules
that a state of the region takes. Where the blended model at such a state has an eigenvalue ``s`` with
``Re s >= 0`` that its inputs do not reach (``rank [A - s I, B] < n``), no gain makes it stable, and no
design exists, whatever its parameters. :func:`reach_notes` tests this at the origin (projected onto the region),
the point about which the automatic sector model is built, and names the mode's states and the input
coefficients that are 0 there but not elsewhere: an input that acts only through a coefficient that vanishes
there (a quadrotor's total thrust on the horizontal velocity, ``B[vx, thrust]``, 0 at hover).
"""

from __future__ import annotations

import numpy as np

__all__ = ["reach_notes"]

#: a singular value of ``[A - s I, B]`` below this x its norm is a rank deficiency
_RANK_TOL = 1e-9
#: an eigenvalue with real part above -this x ||A|| counts as not decaying
_MARGINAL = 1e-9


def reach_notes(ts) -> tuple[str, ...]:
    """One note per eigenvalue at the origin that is not decaying and that the inputs do not reach (see the module
    docstring); none for a model of operating points, or where every such mode is reached."""
    if ts.kind not in ("sector", "sector_auto", "linear") or ts.m == 0:
        return ()
    plant = ts.plant
    lo = np.where(np.isnan(plant.region_lo), 0.0, plant.region_lo)
    hi = np.where(np.isnan(plant.region_hi), 0.0, plant.region_hi)
    h = ts.memberships(np.clip(np.zeros(ts.n), lo, hi))
    A = sum(hi_ * lm.A for hi_, lm in zip(h, ts.local_models))
    B = sum(hi_ * lm.B for hi_, lm in zip(h, ts.local_models))
    size = max(float(np.linalg.norm(np.hstack([A, B]), 2)), 1e-300)
    notes, seen = [], []
    for s in np.linalg.eigvals(A):
        if s.real < -_MARGINAL * size or any(abs(s - t) <= 1e-6 * size for t in seen):
            continue
        seen.append(s)
        M = np.hstack([A - s * np.eye(ts.n), B])
        U, S, _ = np.linalg.svd(M)  # n singular values: M is n x (n + m)
        left = U[:, S <= _RANK_TOL * size]  # w with w^T (A - s I) = 0 and w^T B = 0
        if not left.size:
            continue
        # the mode's own states: the eigenvectors of s that the unreached left vectors see (px of an integrator
        # px' = vx, not the vx that its left vector also holds); the left vectors where none is found
        _, Sa, Vh = np.linalg.svd(A - s * np.eye(ts.n))
        right = Vh[Sa <= _RANK_TOL * size].conj().T
        seen_by = right @ (left.conj().T @ right).conj().T if right.size else left
        weight = np.max(np.abs(seen_by if np.max(np.abs(seen_by), initial=0.0) > 0 else left), axis=1)
        states = [plant.state_names[j] for j in np.flatnonzero(weight > 1e-6 * weight.max())]
        rows = {plant.state_names[j] for j in np.flatnonzero(np.max(np.abs(left), axis=1) > 1e-6)}
        vanish = [
            f"B[{plant.state_names[i]}, {plant.input_names[k]}]"
            for i in range(ts.n)
            for k in range(ts.m)
            if plant.state_names[i] in rows
            and abs(B[i, k]) <= _RANK_TOL * size
            and any(abs(lm.B[i, k]) > _RANK_TOL * size for lm in ts.local_models)
        ]
        val = f"{s.real:.3g}" if abs(s.imag) <= _RANK_TOL * size else f"{s.real:.3g} +- {abs(s.imag):.3g}j"
        notes.append(
            f"at the origin the inputs do not reach the mode s = {val} of {', '.join(states)}: no feedback of this "
            "model makes it decay, so no design exists (LMI (45) is infeasible whatever sigma and gamma)"
            + (
                f"; {', '.join(vanish)} {'is' if len(vanish) == 1 else 'are'} 0 there and not elsewhere: an input "
                "acting only through a coefficient that vanishes at the origin cannot act there; write the equations "
                "about a point where it acts (its input as a deviation, b.operating_point)"
                if vanish
                else ""
            )
        )
    return tuple(notes)
