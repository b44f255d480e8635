"""The ranges the generated C accepts: of each measurement ``y`` (:func:`output_range`), and of the initial
states ``init_from_y`` and ``init`` take (:func:`initial_range`). Outside them a call returns 3 and changes
nothing; each range is checked, by evaluating the step along its edges, to give finite numbers.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..design import Design

__all__ = []  # internal: fte_casadi.codegen._generate writes them into the C


#: the margin the range check of y adds on each side of an output's range over the region, as a
#: fraction of that range's width: an output free of sensor faults ...
Y_MARGIN = 0.1
#: ... and an output with a sensor fault, whose size the plant does not declare
Y_FAULT_MARGIN = 1.0
#: the bound on |y| where the range is not known (a state without bounds, a design document without
#: the region): no product of two such numbers overflows (1e150^2 < DBL_MAX, 1e18^2 < FLT_MAX)
Y_FALLBACK = {"double": 1e150, "float": 1e18}
#: points per output along each side of its margin where the step is evaluated before that margin is kept
_MARGIN_POINTS = 17


def output_range(design: Design, fn: ca.Function | None = None, real: str = "double") -> dict:
    """The range the generated C accepts for each measurement ``y_k`` (outside it the step returns 3 and
    changes nothing).

    It is ``C_k x`` over the plant's region (the box ``checks["region"]`` of the design document),
    widened on each side by :data:`Y_MARGIN` of its width (:data:`Y_FAULT_MARGIN` for an output with a
    sensor fault, whose size is not declared). When ``fn`` (the step) is given, the step is evaluated
    along each widened side, the other outputs at the middle of their ranges and ``z`` such that
    ``xbarhat`` is the nominal start: where it is not finite (a premise outside its domain, such as the
    square root of a negative level), the margin of that side is halved until it is, down to none.
    Where the range is unknown, ``|y_k| <=`` :data:`Y_FALLBACK`. Returns ``{"lo", "hi", "margin_lo",
    "margin_hi", "known"}``, per output.
    """
    C, Df = np.asarray(design.C, float), np.asarray(design.Df, float)
    p, n = C.shape
    big = Y_FALLBACK[real]
    xlo, xhi = _region(design)
    lo, hi = np.zeros(p), np.zeros(p)
    for k in range(p):
        a = np.where(C[k] > 0, xlo, xhi) * C[k]
        b = np.where(C[k] > 0, xhi, xlo) * C[k]
        used = C[k] != 0
        lo[k], hi[k] = np.sum(a[used]), np.sum(b[used])
    known = np.isfinite(lo) & np.isfinite(hi) & (np.abs(lo) < big) & (np.abs(hi) < big)
    width = np.where(known, hi - lo, 0.0)
    frac = np.where(np.any(Df != 0, axis=1), Y_FAULT_MARGIN, Y_MARGIN)
    m_lo, m_hi = frac * width, frac * width
    if fn is not None and np.any(known):
        H = np.asarray(design.H, float)
        xbar0 = np.asarray(design.xbar0, float)

        every = _every_value(fn)

        def finite(ys: np.ndarray) -> bool:
            N = ys.shape[1]
            zs = xbar0[:, None] - H @ ys
            if fn.size1_in(0) > zs.shape[0]:  # a latched accommodation gate's latches, off as init sets them
                zs = np.vstack([zs, np.zeros((fn.size1_in(0) - zs.shape[0], N))])
            return bool(np.all(np.isfinite(np.array(every.map(N)(zs, ys)))))

        mid = np.where(known, 0.5 * (lo + hi), 0.0)
        for k in np.flatnonzero(known):
            for side, edge, margin in (("lo", lo[k], m_lo), ("hi", hi[k], m_hi)):
                sign = -1.0 if side == "lo" else 1.0
                while True:
                    ys = np.tile(mid[:, None], (1, _MARGIN_POINTS))
                    ys[k] = edge + sign * np.linspace(0.0, margin[k], _MARGIN_POINTS)
                    if finite(ys) or margin[k] == 0.0:
                        break
                    margin[k] = 0.0 if margin[k] < 1e-3 * width[k] else 0.5 * margin[k]
    ylo = np.where(known, lo - m_lo, -big)
    yhi = np.where(known, hi + m_hi, big)
    return {"lo": ylo, "hi": yhi, "margin_lo": m_lo, "margin_hi": m_hi, "known": known}


def _region(design: Design) -> tuple[np.ndarray, np.ndarray]:
    """The plant's region (``checks["region"]`` of the design document) as two arrays, NaN where a state has
    no bound (or the document's region is malformed)."""
    n = int(design.dims.n)
    region = design.checks.get("region") if isinstance(design.checks, dict) else None
    xlo = xhi = np.full(n, np.nan)
    if isinstance(region, dict):
        try:
            xlo = np.array([np.nan if v is None else float(v) for v in region.get("lo", [])], float)
            xhi = np.array([np.nan if v is None else float(v) for v in region.get("hi", [])], float)
        except (TypeError, ValueError):
            xlo = xhi = np.full(n, np.nan)
        if xlo.shape != (n,) or xhi.shape != (n,) or np.any(xlo > xhi):
            xlo = xhi = np.full(n, np.nan)
    return xlo, xhi


def initial_range(design: Design, fn: ca.Function, y_range: dict, real: str = "double") -> dict:
    """The ranges the generated C accepts for an initial state: ``xbar0`` of ``init_from_y`` and ``z0`` of
    ``init`` (outside them each returns 3 and changes nothing).

    ``xbar0 = [xhat0; fdothat0; fhat0]``: each state in the plant's region widened on each side by
    :data:`Y_MARGIN` of its width, less where the step would not be finite there (the step evaluated along each
    widened side, ``y`` at the middle of its accepted range, as :func:`output_range` does), and
    ``|v| <=`` :data:`Y_FALLBACK` for a state without bounds and for the fault estimates, whose size the plant
    does not declare. ``z0``: ``|z0_i|`` at most the largest ``|xbar0_i - (H y0)_i|`` over the ranges of
    ``xbar0`` and ``y`` (``y_range``): a magnitude, so that zero (the state ``init(s, NULL)`` sets) is accepted
    too. Returns ``{"xbar_lo", "xbar_hi", "z_lo", "z_hi"}``; raises ``ValueError`` naming the state where the
    nominal start ``[x0; 0; 0]`` lies outside.
    """
    n, nbar = int(design.dims.n), int(design.dims.nbar)
    big = Y_FALLBACK[real]
    xlo, xhi = _region(design)
    known = np.isfinite(xlo) & np.isfinite(xhi) & (np.abs(xlo) < big) & (np.abs(xhi) < big)
    width = np.where(known, xhi - xlo, 0.0)
    margin = Y_MARGIN * width
    H = np.asarray(design.H, float)
    ymid = np.where(y_range["known"], 0.5 * (y_range["lo"] + y_range["hi"]), 0.0)
    every = _every_value(fn)
    latches = fn.size1_in(0) - nbar  # a latched accommodation gate's latches, off as init sets them

    def finite(xbars: np.ndarray) -> bool:
        N = xbars.shape[1]
        zs = np.vstack([xbars - (H @ ymid)[:, None], np.zeros((latches, N))])
        return bool(np.all(np.isfinite(np.array(every.map(N)(zs, np.tile(ymid[:, None], (1, N)))))))

    mid = np.where(known, 0.5 * (xlo + xhi), 0.0)
    for k in np.flatnonzero(known):
        for sign, edge in ((-1.0, xlo[k]), (1.0, xhi[k])):
            m = margin[k]
            while True:
                xb = np.zeros((nbar, _MARGIN_POINTS))
                xb[:n] = mid[:, None]
                xb[k] = edge + sign * np.linspace(0.0, m, _MARGIN_POINTS)
                if finite(xb) or m == 0.0:
                    break
                m = 0.0 if m < 1e-3 * width[k] else 0.5 * m
            if sign < 0:
                xlo[k] = edge - m
            else:
                xhi[k] = edge + m
    lo, hi = np.full(nbar, -big), np.full(nbar, big)
    lo[:n], hi[:n] = np.where(known, xlo, -big), np.where(known, xhi, big)
    x0 = np.asarray(design.xbar0, float)
    out = np.flatnonzero((x0 < lo) | (x0 > hi))
    if out.size:
        k = int(out[0])
        raise ValueError(f"the nominal start x0 has state {k + 1} = {x0[k]:g}, outside the range [{lo[k]:g}, "
                         f"{hi[k]:g}] of the plant's region")  # fmt: skip
    Hlo, Hhi = H * y_range["lo"][None, :], H * y_range["hi"][None, :]
    hy_lo, hy_hi = np.minimum(Hlo, Hhi).sum(axis=1), np.maximum(Hlo, Hhi).sum(axis=1)
    z_top = np.maximum(np.abs(lo - hy_hi), np.abs(hi - hy_lo))  # a magnitude: z0 = 0 (and -z0) accepted too
    return {"xbar_lo": lo, "xbar_hi": hi, "z_lo": -z_top, "z_hi": z_top}


def _every_value(fn: ca.Function) -> ca.Function:
    """``(z, y) ->`` every intermediate value of the step ``fn`` (an ``SX`` Function), branches that an
    ``if_else`` discards included: a NaN swallowed later (``fmax(NaN, lo)`` is ``lo``) still shows, as it
    would as a floating-point exception in the C."""
    z, y = ca.SX.sym("z", fn.size1_in(0)), ca.SX.sym("y", fn.size1_in(1))
    outs = ca.vertcat(*[ca.vec(o) for o in fn.call([z, y])])
    seen, nodes = set(), []
    stack = [outs[k] for k in range(outs.numel())]
    while stack:
        e = stack.pop()
        key = e.element_hash()
        if key in seen:
            continue
        seen.add(key)
        nodes.append(e)
        stack.extend(e.dep(i) for i in range(e.n_dep()))
    return ca.Function("every", [z, y], [ca.vertcat(*nodes)])
