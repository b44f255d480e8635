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

import hashlib
import threading
from typing import NamedTuple

import casadi as ca
import numpy as np

from ..errors import BoundsError
from ._direct import direct

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
    out = 2.0 * out.reshape(k, -1)
    # a margin of 1e-12, never more than 1e-12 of the largest gradient in that direction: a premise of tiny values
    # over states in large units (a gradient of 1e-15) keeps bounds as tight as in units where it is of order 1
    return (out + 1e-12 * np.minimum(1.0, np.max(out, axis=1, keepdims=True))).T


def _extremum(FG, grid, vals, grads, lo, hi, hw, sign, shape, max_searches=_MAX_SEARCHES):
    """Minimum of sign*f over the box (``FG``: ``x -> (f, grad f)``); returns (value, gap)."""
    v = sign * vals
    cell_lb = v - _local_lipschitz(grads, shape) @ hw
    order = np.argsort(v)
    best = v[order[0]]
    # a cell must be able to beat the best value by more than round-off of the function's size (in any unit)
    tol = 1e-9 * max(abs(best), float(np.max(np.abs(vals), initial=0.0)))
    cand = np.flatnonzero(cell_lb < best - tol)
    cand = cand[np.argsort(v[cand])]
    starts = list(order[:10]) + [c for c in cand if c not in set(order[:10])]  # noqa: C401
    searched = set()

    FGd = direct(FG)

    def fun(xx):
        f, g = FGd(xx)
        return sign * float(f[0]), sign * g

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


def _states_used(expr: ca.SX, x: ca.SX) -> tuple[int, ...]:
    """The indices of the states ``expr`` depends on."""
    return tuple(j for j in range(x.numel()) if ca.depends_on(expr, x[j]))


class _Sampled(NamedTuple):
    """``expr`` as a function of the states it uses (``idx``), and its values and gradients on a grid of about
    ``samples`` points over their box: what :func:`_extremum` searches."""

    FG: (
        ca.Function
    )  # x -> (f, grad f) in one Function: the gradient's reverse sweep reuses the value's forward one
    points: np.ndarray  # (k, N): the grid, one column a point
    vals: np.ndarray  # (N,)
    grads: np.ndarray  # (k, N)
    lo: np.ndarray
    hi: np.ndarray
    per: int  # grid points per axis

    @staticmethod
    def function(expr: ca.SX, x: ca.SX, idx: tuple[int, ...]) -> ca.Function:
        """``expr`` and its gradient as a function of the states it uses (the others set to 0)."""
        xs = ca.vertcat(*[x[j] for j in idx])
        others = [j for j in range(x.numel()) if j not in idx]
        e = (
            ca.substitute(expr, ca.vertcat(*[x[j] for j in others]), ca.DM.zeros(len(others)))
            if others
            else expr
        )
        return ca.Function("FG", [xs], [e, ca.gradient(e, xs)])

    @classmethod
    def of(cls, FG: ca.Function, idx: tuple[int, ...], lo: np.ndarray, hi: np.ndarray, samples: int):
        k = len(idx)
        per = max(3, int(round(samples ** (1.0 / k))))
        lo_s, hi_s = lo[list(idx)], hi[list(idx)]
        axes = [np.linspace(a, b, per) for a, b in zip(lo_s, hi_s)]
        points = np.array(np.meshgrid(*axes, indexing="ij")).reshape(k, -1)
        f, g = FG.map(points.shape[1])(points)  # one mapped call for both
        return cls(FG, points, np.array(f).ravel(), np.array(g).reshape(k, -1), lo_s, hi_s, per)

    def first_not_finite(self) -> np.ndarray | None:
        """The first grid point where the expression is not finite, or None."""
        bad = np.flatnonzero(~np.isfinite(self.vals))
        return self.points[:, bad[0]] if bad.size else None

    def extrema(self, signs: tuple[float, ...], max_searches: int) -> list[tuple[float, float]]:
        """``(value, gap)`` of :func:`_extremum` for each sign (1: the minimum, -1: the maximum)."""
        k = self.points.shape[0]
        grads = self.grads.copy()
        grads[~np.isfinite(grads)] = 0.0
        hw = (self.hi - self.lo) / (self.per - 1) / 2
        return [_extremum(self.FG, self.points, self.vals, grads, self.lo, self.hi, hw, sign, (self.per,) * k,
                          max_searches) for sign in signs]  # fmt: skip


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
    idx = _states_used(expr, x)
    if not idx:
        val = float(ca.Function("c", [x], [expr])(np.zeros(x.numel())))
        return val, val, idx, 0.0
    pt, found = _searched(expr, x, idx, lo, hi, _SAMPLES, (1.0, -1.0), max_searches)
    if pt is not None:
        where = ", ".join(f"{state_names[j]} = {v:g}" for j, v in zip(idx, pt))
        raise BoundsError(
            f"premise {name!r} is not finite at {where}: define it there (e.g. with casadi.if_else for a "
            "removable singularity such as sin(v)/v at 0) or shrink the region",
            "not finite",
            where,
        )
    (mn, gap1), (mx, gap2) = found
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
    idx = _states_used(expr, x)
    if not idx:
        return float(ca.Function("c", [x], [expr])(np.zeros(x.numel())))
    _, ((mx, _),) = _searched(expr, x, idx, lo, hi, samples, (-1.0,), max_searches)
    return float(mx)


def _searched(expr, x, idx, lo, hi, samples, signs, max_searches):
    """``(first point not finite or None, extrema)`` of :meth:`_Sampled.extrema` (no search where a point is not
    finite). A function of the expression (as CasADi serialises it: exact; kept as its SHA-256), the box, the grid
    and the searches alone: found once per process for the last few hundred (a plant derived again, or its other
    covers, asks the same bounds)."""
    FG = _Sampled.function(expr, x, idx)
    key = (hashlib.sha256(FG.serialize().encode()).digest(), np.asarray(lo, float)[list(idx)].tobytes(),
           np.asarray(hi, float)[list(idx)].tobytes(), samples, signs, max_searches)  # fmt: skip
    if key in _FOUND:
        return _FOUND[key]
    grid = _Sampled.of(FG, idx, lo, hi, samples)
    pt = grid.first_not_finite()
    out = (pt, None if pt is not None else grid.extrema(signs, max_searches))
    with _FOUND_LOCK:  # searches in threads evict one at a time
        _FOUND[key] = out
        while len(_FOUND) > _FOUND_KEPT:
            _FOUND.pop(next(iter(_FOUND)))
    return out


#: the searches' answers in this process, oldest first (:func:`_searched`)
_FOUND: dict = {}
_FOUND_KEPT = 512
_FOUND_LOCK = threading.Lock()


def minimize(*args, **kwargs):
    """scipy.optimize.minimize, imported on the first call (``import fte_casadi`` does not pay the 0.2-0.5 s
    scipy.optimize takes to load); a module attribute, so a caller can wrap it (tests/test_ts_quadrotor.py counts
    the searches' work)."""
    from scipy.optimize import minimize as scipy_minimize

    return scipy_minimize(*args, **kwargs)
