"""Membership functions as CasADi Functions (sector products, triangular), and the
scheduling map from measured signals used by the observer/controller step."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import triangular_memberships

__all__ = ["sector_memberships", "rule_vertices", "triangular_membership_fn", "scheduling_from_measurements"]


def rule_vertices(mins, maxs) -> np.ndarray:
    """Premise values of each rule, in the documented order (docs/interface.md).

    Rule i takes, for each premise, the bound ``max`` then ``min``, the first premise varying
    slowest: for one premise rule 1 is at ``max``, rule 2 at ``min``.
    """
    q = len(mins)
    r = 2**q
    out = np.zeros((r, q))
    for i in range(r):
        for k in range(q):
            bit = (i >> (q - 1 - k)) & 1
            out[i, k] = maxs[k] if bit == 0 else mins[k]
    return out


def sector_memberships(mins, maxs) -> ca.Function:
    """``premise values (q) -> h (2^q)``: products of the two sector weights per premise.

    Premise values are saturated to their bounds, so the memberships stay a convex sum
    (non-negative, summing to one) even outside the region.
    """
    q = len(mins)
    z = ca.SX.sym("z", q)
    wmax, wmin = [], []
    for k in range(q):
        s = ca.fmin(ca.fmax(z[k], mins[k]), maxs[k])
        wmax.append((s - mins[k]) / (maxs[k] - mins[k]))
        wmin.append((maxs[k] - s) / (maxs[k] - mins[k]))
    h = []
    for i in range(2**q):
        term = ca.SX(1.0)
        for k in range(q):
            term = term * (wmax[k] if ((i >> (q - 1 - k)) & 1) == 0 else wmin[k])
        h.append(term)
    return ca.Function("memberships", [z], [ca.vertcat(*h)], ["premises"], ["h"])


def triangular_membership_fn(centres) -> ca.Function:
    """``scheduling value -> h (r)``: triangular memberships, saturated outside the centres."""
    v = ca.SX.sym("v")
    return ca.Function(
        "memberships", [v], [ca.vertcat(*triangular_memberships(v, np.asarray(centres)))], ["premises"], ["h"]
    )


def scheduling_from_measurements(ts) -> tuple[ca.Function, list[str]]:
    """``(y, xhat) -> h``: memberships computed from measured signals where possible.

    A state a premise depends on is read from the output that measures it alone and is free
    of sensor faults (``C[k] = e_j``, ``Df[k] = 0``); otherwise its estimate ``xhat_j`` is used.
    Returns the Function and, per state used, where it is read from (for reports).
    """
    plant = ts.plant
    n, p = ts.n, ts.p
    y = ca.SX.sym("y", p)
    xh = ca.SX.sym("xhat", n)
    src = []
    xs = []
    for j in range(n):
        rows = [
            k for k in range(p) if np.count_nonzero(ts.C[k]) == 1 and ts.C[k, j] != 0 and not np.any(ts.Df[k])
        ]
        if rows:
            xs.append(y[rows[0]] / ts.C[rows[0], j])
            src.append(f"{plant.state_names[j]} <- y[{rows[0]}] ({plant.output_names[rows[0]]})")
        else:
            xs.append(xh[j])
            src.append(f"{plant.state_names[j]} <- xhat[{j}] (estimate)")
    xv = ca.vertcat(*xs)
    h = ts.membership_fn(ts.premise_fn(xv))
    used = sorted({j for pr in ts.premises for j in pr.states})
    return ca.Function("scheduling", [y, xh], [h], ["y", "xhat"], ["h"]), [src[j] for j in used]
