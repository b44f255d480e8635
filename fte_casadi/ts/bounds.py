"""Bounds of a premise expression over a box, found globally and certified by a Lipschitz argument.

Method: evaluate the expression (and its gradient) on a dense grid of the states it depends
on; a cell of half-widths ``hw`` around a grid point ``c`` cannot hold a value below
``f(c) - sum_j L_j hw_j`` where ``L_j`` bounds ``|df/dx_j|`` (the sampled maximum times a
safety factor of 2, taken over the cell's grid neighbours). Every cell whose lower bound could beat the best value found is searched
by a bounded local optimiser (L-BFGS-B) started at its centre; the bound is the best value
found, widened to the smallest cell bound that was not searched, if any (``gap`` says by how
much). An extremum between grid points is therefore found by the local search from the
neighbouring cell, not missed.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
from scipy.optimize import minimize

from ..errors import BoundsError

__all__ = ["premise_bounds", "certified_max"]

_SAMPLES = 200_001
_MAX_SEARCHES = 200


def _local_lipschitz(grads: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Per cell and direction: 2 x the largest |gradient| at the cell and its grid neighbours."""
    k = grads.shape[0]
    g = np.abs(grads).reshape((k, *shape))
    out = g.copy()
    for ax in range(1, k + 1):
        lo = [slice(None)] * (k + 1)
        hi = [slice(None)] * (k + 1)
        lo[ax], hi[ax] = slice(0, -1), slice(1, None)
        out[tuple(lo)] = np.maximum(out[tuple(lo)], g[tuple(hi)])
        out[tuple(hi)] = np.maximum(out[tuple(hi)], g[tuple(lo)])
    return (2.0 * out.reshape(k, -1) + 1e-12).T


def _extremum(FG, grid, vals, grads, lo, hi, hw, sign, shape, max_searches=_MAX_SEARCHES):
    """Minimum of sign*f over the box (``FG``: ``x -> (f, grad f)``); returns (value, gap)."""
    v = sign * vals
    cell_lb = v - _local_lipschitz(grads, shape) @ hw
    order = np.argsort(v)
    best = v[order[0]]
    tol = 1e-9 * (1.0 + abs(best))  # a cell must be able to beat the best value by more than round-off
    cand = np.flatnonzero(cell_lb < best - tol)
    cand = cand[np.argsort(v[cand])]
    starts = list(order[:10]) + [c for c in cand if c not in set(order[:10])]  # noqa: C401
    searched = set()

    def fun(xx):
        f, g = FG(xx)
        return sign * float(f), sign * np.array(g).ravel()

    top = set(order[:10])
    for k in starts:
        if len(searched) >= max_searches:
            break
        if cell_lb[k] >= best - tol and k not in top:
            continue  # the best value found since cannot be beaten in this cell: nothing to search
        searched.add(int(k))
        res = minimize(fun, grid[:, k], jac=True, method="L-BFGS-B", bounds=list(zip(lo, hi)))
        if np.isfinite(res.fun) and res.fun < best:
            best = float(res.fun)
    rest = [c for c in cand if int(c) not in searched and cell_lb[c] < best - tol]
    gap = 0.0
    if rest:
        lb = float(np.min(cell_lb[rest]))
        if lb < best - tol:
            gap = best - lb
            best = lb
    return sign * best, gap


def _value_and_gradient(xs: ca.SX, e: ca.SX) -> ca.Function:
    """``x -> (f, grad f)`` in one Function: the gradient's reverse sweep reuses the value's forward one, so a
    grid costs one evaluation of both instead of two."""
    return ca.Function("FG", [xs], [e, ca.gradient(e, xs)])


def _on_grid(FG: ca.Function, grid: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Values (N,) and gradients (k, N) of ``FG`` at the columns of ``grid`` (k, N), one mapped call."""
    k, N = grid.shape
    f, g = FG.map(N)(grid)
    return np.array(f).ravel(), np.array(g).reshape(k, N)


def premise_bounds(
    name: str,
    expr: ca.SX,
    x: ca.SX,
    lo: np.ndarray,
    hi: np.ndarray,
    state_names,
    allow_constant: bool = False,
    max_searches: int = _MAX_SEARCHES,
) -> tuple[float, float, tuple[int, ...], float]:
    """Global min and max of ``expr(x)`` over the box ``[lo, hi]`` (only the states it uses).

    Returns ``(min, max, states, gap)``; ``gap`` > 0 means the bounds were widened by that
    amount because not every suspicious cell could be searched. Raises :class:`BoundsError`
    when the expression is not finite somewhere on the grid, unbounded, or (unless
    ``allow_constant``) constant over the box.
    """
    idx = tuple(j for j in range(x.numel()) if ca.depends_on(expr, x[j]))
    if not idx:
        val = float(ca.Function("c", [x], [expr])(np.zeros(x.numel())))
        return val, val, idx, 0.0
    xs = ca.vertcat(*[x[j] for j in idx])
    others = [j for j in range(x.numel()) if j not in idx]
    e = ca.substitute(expr, ca.vertcat(*[x[j] for j in others]), ca.DM.zeros(len(others))) if others else expr
    FG = _value_and_gradient(xs, e)
    k = len(idx)
    per = max(3, int(round(_SAMPLES ** (1.0 / k))))
    lo_s, hi_s = lo[list(idx)], hi[list(idx)]
    axes = [np.linspace(a, b, per) for a, b in zip(lo_s, hi_s)]
    grid = np.array(np.meshgrid(*axes, indexing="ij")).reshape(k, -1)
    vals, grads = _on_grid(FG, grid)
    bad = ~np.isfinite(vals)
    if np.any(bad):
        pt = grid[:, np.flatnonzero(bad)[0]]
        where = ", ".join(f"{state_names[j]} = {v:g}" for j, v in zip(idx, pt))
        raise BoundsError(
            f"premise {name!r} is not finite at {where}: define it there (e.g. with casadi.if_else for a "
            "removable singularity such as sin(v)/v at 0) or shrink the region",
            "not finite",
            where,
        )
    grads[~np.isfinite(grads)] = 0.0
    hw = (hi_s - lo_s) / (per - 1) / 2
    mn, gap1 = _extremum(FG, grid, vals, grads, lo_s, hi_s, hw, 1.0, (per,) * k, max_searches)
    mx, gap2 = _extremum(FG, grid, vals, grads, lo_s, hi_s, hw, -1.0, (per,) * k, max_searches)
    if not (np.isfinite(mn) and np.isfinite(mx)):
        raise BoundsError(f"premise {name!r} is unbounded over the region; shrink the region", "unbounded")
    if mx - mn < 1e-12 and not allow_constant:
        raise BoundsError(
            f"premise {name!r} is constant ({mn:g}) over the region: it schedules nothing; remove it "
            "and write the constant into the equations",
            "constant",
        )
    return mn, mx, idx, max(gap1, gap2)


def certified_max(
    expr: ca.SX, x: ca.SX, lo: np.ndarray, hi: np.ndarray, samples: int = 20_001, max_searches: int = 20
) -> float:
    """An upper bound of ``expr(x)`` over the box ``[lo, hi]`` by the same search as :func:`premise_bounds`
    (a grid of ``samples`` points, every cell whose Lipschitz bound could beat the best value searched
    locally, the bound widened by whatever was not searched). Used to grow a polytope's facets until they
    provably contain the premises' image."""
    idx = tuple(j for j in range(x.numel()) if ca.depends_on(expr, x[j]))
    if not idx:
        return float(ca.Function("c", [x], [expr])(np.zeros(x.numel())))
    xs = ca.vertcat(*[x[j] for j in idx])
    others = [j for j in range(x.numel()) if j not in idx]
    e = ca.substitute(expr, ca.vertcat(*[x[j] for j in others]), ca.DM.zeros(len(others))) if others else expr
    FG = _value_and_gradient(xs, e)
    k = len(idx)
    per = max(3, int(round(samples ** (1.0 / k))))
    lo_s, hi_s = lo[list(idx)], hi[list(idx)]
    grid = np.array(
        np.meshgrid(*[np.linspace(a, b, per) for a, b in zip(lo_s, hi_s)], indexing="ij")
    ).reshape(k, -1)
    vals, grads = _on_grid(FG, grid)
    grads[~np.isfinite(grads)] = 0.0
    hw = (hi_s - lo_s) / (per - 1) / 2
    mx, _ = _extremum(FG, grid, vals, grads, lo_s, hi_s, hw, -1.0, (per,) * k, max_searches)
    return float(mx)
