"""The plant's numbers are finite: parameters, output matrices, and the equations at test points.

A NaN or an infinity in a coefficient (a parameter read from a file that held none, an overflow in
a hand computation) propagates into every matrix of the T-S model; downstream, an integrator chases
it with ever smaller steps and an SDP solver fails without saying why. :func:`check_finite` refuses
it once, in ``build()``, naming the entry and a point where it shows.

The equations (drift, diffusion, premises, with the premises substituted) are evaluated at the
region's centre and corners (:func:`region_points`) with the inputs at the reference and the unknown
inputs and faults at 0. A row that is not finite there is refused when it holds a non-finite
constant, or when it is not finite at any of the points. A row with finite coefficients that is
singular only at some points (``sin(x)/x`` unguarded at 0, ``1/x1`` on a region through 0) is left
to the T-S derivation, which explains a singularity by name (:mod:`fte_casadi.ts._auto_checks`,
:func:`fte_casadi.ts._premise_bounds.premise_bounds`).
"""

from __future__ import annotations

import itertools
import math

import casadi as ca
import numpy as np

from ..errors import PlantError

__all__ = []  # public: docs/api.md

#: up to this many states every corner of the region is a test point (2^n); beyond, the centre of
#: every face and the two opposite corners (lowest, highest)
MAX_CORNERS = 10


def region_points(lo: np.ndarray, hi: np.ndarray, x0: np.ndarray) -> tuple[np.ndarray, list[str]]:
    """Columns of test states (centre first) and what each is; a state without bounds stays at x0."""
    free = np.isnan(lo)
    lo = np.where(free, x0, lo)
    hi = np.where(free, x0, hi)
    n = lo.size
    centre = 0.5 * (lo + hi)
    pts, what = [centre], ["the region's centre"]
    if n <= MAX_CORNERS:
        for bits in itertools.product((0, 1), repeat=n):
            pts.append(np.where(np.array(bits, bool), hi, lo))
            what.append("a corner of the region")
    else:
        pts += [lo, hi]
        what += ["the region's lowest corner", "the region's highest corner"]
        for j in range(n):
            for side in (lo, hi):
                c = centre.copy()
                c[j] = side[j]
                pts.append(c)
                what.append("the centre of a face of the region")
    return np.array(pts).T, what


def _bad_constant(expr: ca.SX, syms: ca.SX) -> float | None:
    """A non-finite constant held by ``expr`` (a scalar), else None."""
    fn = ca.Function("c", [syms], [expr])
    for k in range(fn.n_instructions()):
        if fn.instruction_id(k) == ca.OP_CONST:
            v = float(fn.instruction_constant(k))
            if not math.isfinite(v):
                return v
    return None


def _where(names, col: np.ndarray) -> str:
    return ", ".join(f"{nm} = {v:.6g}" for nm, v in zip(names, col))


def check_finite(
    *,
    params: dict,
    C: np.ndarray,
    Df: np.ndarray,
    state_names,
    output_names,
    fault_names,
    x: ca.SX,
    u: ca.SX,
    d: ca.SX,
    f: ca.SX,
    d2: ca.SX,
    rows: dict[str, tuple[ca.SX, list[str]]],
    lo: np.ndarray,
    hi: np.ndarray,
    x0: np.ndarray,
    u_nominal: np.ndarray,
) -> None:
    """Raise :class:`~fte_casadi.errors.PlantError` for a non-finite parameter, output coefficient or
    equation (``rows``: ``{kind: (column expression in x, u, d, f, d2; row names)}``)."""
    for key, v in params.items():
        if not math.isfinite(float(v)):
            raise PlantError(f"parameter {key!r} is {float(v)}: every parameter must be a finite number")
    for mat, cols, label in ((C, state_names, "state"), (Df, fault_names, "fault")):
        bad = np.argwhere(~np.isfinite(mat))
        if bad.size:
            k, j = bad[0]
            raise PlantError(
                f"output {output_names[k]!r}: the coefficient of {label} {cols[j]!r} is {mat[k, j]}; "
                "every output coefficient must be finite"
            )
    X, what = region_points(lo, hi, x0)
    N = X.shape[1]
    syms = ca.vertcat(x, u, d, f, d2)
    U = np.tile(np.asarray(u_nominal, float).reshape(-1, 1), (1, N))
    rest = np.zeros((d.numel() + f.numel() + d2.numel(), N))
    args = np.vstack([X, U, rest])
    for kind, (column, names) in rows.items():
        if column.numel() == 0:
            continue
        fn = ca.Function("eq", [syms], [column]).map(N)
        vals = np.array(fn(args)).reshape(column.numel(), N)
        for k in range(column.numel()):
            finite = np.isfinite(vals[k])
            if finite.all():
                continue
            const = _bad_constant(column[k], syms)
            if const is None and finite.any():
                continue  # a singularity at some points: the derivation names it
            i = int(np.argmin(finite))
            held = (
                f"holds the coefficient {const}"
                if const is not None
                else "is not finite anywhere it was evaluated"
            )
            raise PlantError(
                f"{kind} {names[k]!r} {held}: it evaluates to {vals[k, i]} at {what[i]} "
                f"({_where(state_names, X[:, i])}, inputs at the reference, unknown inputs and faults 0); "
                "give every coefficient a finite value"
            )
