"""What is feasible: the bounds an infeasible design names, and the frontier of ``--explore``.

gamma and sigma enter LMI (45) linearly (``(gamma1^2 - gamma^2) I`` in its d block, ``+ sigma I``
in its first block), so one SDP each gives

- ``gamma_min(sigma, gamma1)``: the smallest gamma for which (45) is feasible (``min g`` with
  ``g = gamma^2`` as an unknown), and
- ``sigma_max(gamma, gamma1)``: the largest sigma for which it is (``gamma = inf``: the d block
  dropped, the supremum over every gamma).

Both are posed with the same per-block margins as the design, so a value slightly inside them
is feasible with margin. A suggestion is only ever printed after the whole design (both steps
and the certificate) has been run at the suggested value and certified.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._augment import Augmented, output_scale, time_scale, units_params, units_scaled, unknown_input_size
from ._conditioned import MARGIN, _step3_numpy, _step3_problem, input_scaling
from ._lmis import lmi45, lmi45_kron, lmi_decay, lmi_decay_kron
from ._sdp import SOLVED, ConicProblem, Layout, Var, affine_lmi

__all__ = ["sigma_max"]  # public: docs/api.md


def _blocks(aug: Augmented) -> tuple[int, int, int, int]:
    return aug.n, aug.n, aug.p, aug.ld


def _units(aug: Augmented) -> list[tuple[float, float, float]]:
    """The posings ``(tau, sy, xmin)`` the bounds are tried in, in order: the plant's own time and output size,
    with the margin ``X~ >= xmin I`` on the X of those units, then the data as they are.

    (45) of a plant in the time ``t / tau`` with outputs ``y / sy`` is the same LMI at ``X~ = tau sy^2 X``
    (:func:`~fte_casadi.design._augment.units_scaled`). In its own units a fast plant's numbers are of order one:
    left as it is, the PMSM's rates of 1e3/s made the conic solver stop inaccurate, at a gamma_min that moved
    with the order of the states. The margin is the weaker of two: ``X >= MARGIN I`` in the plant's units
    (``xmin = MARGIN tau sy^2``), the same problem as the data used as they are, or ``X~ >= MARGIN I`` where that
    absolute margin would exclude every X (``tau sy^2 > 1``, a slow plant measured in small units, e.g. minutes
    and mm: 1e8). Neither posing suits every plant (a flexible joint's fast motor and slow link fail Clarabel in
    its own units and solve as given), so :func:`_bound` tries both."""
    tau, sy = time_scale(aug), output_scale(aug)
    own = (tau, sy, MARGIN * min(1.0, tau * sy**2))
    return [own] if tau * sy**2 > 1.0 or (tau == 1.0 and sy == 1.0) else [own, (1.0, 1.0, MARGIN)]


def _d_size(aug: Augmented) -> float:
    """The size the unknown inputs are posed in (:func:`~fte_casadi.design._augment.unknown_input_size`): d's
    block of (45) meets X only through ``Bd``, so this change of d's unit leaves X alone and the margins (the
    d block's is relative) as they are, whatever the time and output units: a plant whose d is in N m and the
    same plant with d in rad/s^2 give the solver the same numbers."""
    return unknown_input_size(aug)


def _problem(aug: Augmented, sigma: float | None, gamma: float | None, gamma1: float, xmin: float = MARGIN):
    """(45) for every rule with one unknown scalar: ``g = gamma^2`` (sigma given) or ``sigma`` (gamma given).

    ``gamma=None`` with ``sigma=None`` means sigma unknown and gamma infinite (d block dropped).
    Returns (layout, lmis, objective) of ``min g`` or ``max sigma``.
    """
    n, m, p, ld = aug.n, aug.m, aug.p, aug.ld
    Su = input_scaling(aug)
    layout = Layout(Var("X", (n, n), True), Var("Y", (m, n)), Var("q", ()))
    k = 2 * n + p + ld
    keep = np.arange(k) if gamma is not None or sigma is not None else np.arange(2 * n + p)
    Ex = np.zeros((k, k))
    Ex[:n, :n] = np.eye(n)
    Ed = np.zeros((k, k))
    Ed[2 * n + p :, 2 * n + p :] = np.eye(ld)
    sub = np.ix_(keep, keep)

    def b(i):
        def f(X, Y, q):
            if sigma is not None:  # q = gamma^2
                M = lmi45(aug, i, X, Su @ Y, sigma, gamma1, gamma1) - q * Ed
                marg = np.diag(
                    np.concatenate([np.full(n, sigma), np.zeros(n), np.ones(p), np.full(ld, gamma1**2)])
                )
            else:  # q = sigma
                M = lmi45(aug, i, X, Su @ Y, 0.0, gamma if gamma is not None else gamma1, gamma1) + q * Ex
                gap = (gamma**2 - gamma1**2) if gamma is not None else 1.0
                marg = np.diag(np.concatenate([np.zeros(n), np.zeros(n), np.ones(p), np.full(ld, gap)]))
            return (M + MARGIN * marg)[sub]

        return f

    lmis = [affine_lmi(f"(45) rule {i + 1}", layout, b(i),
                       kron=("X", [(U[:, keep], V[:, keep]) for U, V in lmi45_kron(aug, i)]))
            for i in range(aug.r)]  # fmt: skip
    eye = np.eye(n)
    lmis.append(affine_lmi("X > 0", layout, lambda X, Y, q: xmin * eye - X, support=layout.support("X"),
                           kron=("X", [(eye, -0.5 * eye)])))  # fmt: skip
    c = np.zeros(layout.size)
    c[layout.index("q")] = 1.0 if sigma is not None else -1.0
    return layout, lmis, c


#: the last answers of :func:`gamma_min` and :func:`sigma_max`: one design asks the same question up to three
#: times (the bound in the refusal, the parameter search, the message), each a conic solve of its own
_MEMO: dict = {}
_MEMO_SIZE = 16


def _memo(fn):
    def wrapper(aug: Augmented, a, gamma1: float, solver: str):
        key = (fn.__name__, id(aug), a, gamma1, solver)
        hit = _MEMO.get(key)
        if hit is not None and hit[0] is aug:  # the entry holds aug itself, so its id was not reused
            return hit[1]
        out = fn(aug, a, gamma1, solver)
        while len(_MEMO) >= _MEMO_SIZE:
            _MEMO.pop(next(iter(_MEMO)))
        _MEMO[key] = (aug, out)
        return out

    wrapper.__name__, wrapper.__doc__, wrapper.__wrapped__ = fn.__name__, fn.__doc__, fn
    return wrapper


def _bound(aug: Augmented, sigma, gamma, gamma1: float, solver: str, value) -> tuple[float | None, str]:
    """Solve the bound problem of :func:`_problem` in each posing of :func:`_units` and map its answer back with
    ``value(q, tau, sy, params)``: the first answer a solver calls optimal, else the most conservative of the
    inaccurate ones (``value`` is oriented so that the smallest is: an inaccurate bound can be off either way),
    else ``(None, status of the first)``. A heavy problem (many PSD rows) takes its first answer."""
    inaccurate, first, sd = [], None, _d_size(aug)
    for tau, sy, xmin0 in _units(aug):
        p = units_params(
            {"sigma": sigma if sigma is not None else 1.0, "gamma": gamma, "gamma1": gamma1}, tau, sy, sd
        )
        for xmin in (xmin0 * f for f in MARGIN_SHRINK):
            layout, lmis, c = _problem(units_scaled(aug, tau, sy, sd), p["sigma"] if sigma is not None else None,
                                       p["gamma"], p["gamma1"], xmin)  # fmt: skip
            prob = ConicProblem(layout, lmis, c)
            res = prob.solve(solver)
            first = first or res.status
            if res.v is None or res.status not in SOLVED:
                break
            u = layout.unpack(res.v)
            v = value(u["q"], tau, sy, p)
            # the margin excluded every X that allows a sigma > 0 (a state measured in small units): a smaller one
            if sigma is None and v <= 0 and np.linalg.eigvalsh(u["X"])[0] <= 2.0 * xmin and not prob.heavy:
                continue
            # a heavy problem's second solve costs more than it tells
            if res.status == "optimal" or prob.heavy:
                return v, res.status
            inaccurate.append((v, res.status))
            break
    return min(inaccurate, key=lambda a: a[0]) if inaccurate else (None, first)


#: the margins ``X >= xmin I`` the bounds try, as factors of :func:`_units`' own: an absolute margin in the states'
#: units excludes every X of a plant with a state measured in small units (a levitation's gap in m, 1e-3 wide: X's
#: smallest eigenvalue 5e-5 where sigma_max = 0.017, and at X >= 1e-3 I the bound said "no sigma > 0"); a smaller
#: margin is tried only where the larger one left no sigma > 0 and X sits on it
MARGIN_SHRINK = (1.0, 1e-3, 1e-6)
#: the status of a bound found by phase 1's bisection in numpy
PHASE1 = "phase 1 (numpy), bisection"
#: the statuses of a bound that was decided: a solver's optimum or proof of infeasibility, or phase 1's bisection
DECIDED = ("optimal", "infeasible", PHASE1)
#: a bound found by phase 1 in numpy is bracketed this tightly (its feasible end is returned)
BRACKET = 1.05
#: at most this many factors of 10 from the start before a bound is given up (the conic solve then)
DECADES = 14


def _decide(aug: Augmented, sigma: float, gamma: float, gamma1: float) -> bool | None:
    """Is step 3's (45) feasible at ``(sigma, gamma, gamma1)``? Decided as the design decides it, by phase 1 in
    numpy (a point, or the duality bound's proof that none exists under its caps); None when it fails."""
    params = {"sigma": sigma, "gamma": gamma, "gamma1": gamma1}
    layout, family, _ = _step3_problem(aug, params, input_scaling(aug))
    out = _step3_numpy(aug, params, layout, [L.at(2 * MARGIN) for L in family[:-1]], keep_infeasible=True)
    return None if out is None else out[1].v is not None


def _heavy(aug: Augmented, gamma1: float) -> bool:
    params = {"sigma": 1.0, "gamma": 2.0 * gamma1 + 1.0, "gamma1": gamma1}
    layout, family, _ = _step3_problem(aug, params, input_scaling(aug))
    return ConicProblem(layout, [L.at(2 * MARGIN) for L in family[:-1]]).heavy


def _edge(feasible_at, x0: float, up_feasible: bool, floor: float = 0.0):
    """The edge of a feasible interval of ``x`` (``feasible_at(x)``: True, False or None), feasible above it
    (``up_feasible``) or below it: ``("edge", x)`` with x the feasible end of a bracket ``BRACKET`` wide,
    ``("none", None)`` when no x tried is feasible, ``("all", x)`` when every x tried is, ``None`` when a
    decision failed. Steps of 10 from ``x0``, then bisection in ``log x``; x stays above ``floor``."""
    toward_feasible = 10.0 if up_feasible else 0.1
    f0 = feasible_at(x0)
    if f0 is None:
        return None
    ok, bad = (x0, None) if f0 else (None, x0)
    x = x0
    for _ in range(DECADES):
        x = x / toward_feasible if f0 else x * toward_feasible
        if x <= floor:
            x = floor + 0.5 * ((ok if ok is not None else bad) - floor)
        f = feasible_at(x)
        if f is None:
            return None
        if f:
            ok = x
        else:
            bad = x
        if ok is not None and bad is not None:
            break
    if ok is None:
        return "none", None
    if bad is None:
        return "all", ok
    while max(ok, bad) / min(ok, bad) > BRACKET:
        mid = math.sqrt(ok * bad) if min(ok, bad) > floor else 0.5 * (ok + bad)
        f = feasible_at(mid)
        if f is None:
            return None
        ok, bad = (mid, bad) if f else (ok, mid)
    return "edge", ok


def _numpy_sigma_max(aug: Augmented, gamma: float, gamma1: float):
    """sigma_max by bisection on phase 1's decisions (a heavy problem: many rules), or None (undecided)."""
    tau, sy = time_scale(aug), output_scale(aug)
    out = _edge(lambda s: _decide(aug, s, gamma, gamma1), 1.0 / (tau * sy) ** 2, up_feasible=False)
    if out is None or out[0] == "all":
        return None
    return (None if out[0] == "none" else float(out[1])), PHASE1


def _numpy_gamma_min(aug: Augmented, sigma: float, gamma1: float):
    """gamma_min by bisection on phase 1's decisions, or None (undecided)."""
    g0 = max(4.0 * gamma1, output_scale(aug) * _d_size(aug))
    out = _edge(lambda g: _decide(aug, sigma, g, gamma1), g0, up_feasible=True, floor=gamma1)
    if out is None:
        return None
    if out[0] == "all":  # feasible down to gamma1: the d block does not bind
        return float(out[1]), PHASE1
    return (None if out[0] == "none" else float(out[1])), PHASE1


@_memo
def gamma_min(aug: Augmented, sigma: float, gamma1: float, solver: str) -> tuple[float | None, str]:
    """The smallest gamma with (45) feasible at ``sigma``, ``gamma1`` (None: no gamma is), and the status.

    Posed in the plant's own time and output size, and as given where that fails (:func:`_units`), so that a plant
    in minutes and millimetres, or one whose rates are 1e3/s, is solved in numbers of order one. A heavy problem
    (many rules) is bisected on phase 1's decisions in numpy (:func:`_edge`) where the conic solve is slow (SCS)
    or fails: on the 64-rule chain's sigma_max, SCS took 56 s, the bisection 11.6 s and Clarabel 2.3 s
    (measured), so Clarabel's answer is kept where it has one.

    A plant without unknown inputs has no d block in (45): gamma bounds nothing there, and the answer is 0 (any
    gamma) where (45) is feasible at ``sigma`` (:func:`sigma_max`), None where it is not."""
    if aug.ld == 0:
        smax, status = sigma_max(aug, None, gamma1, solver)
        return (0.0 if smax is not None and sigma < smax else None), status
    numpy = _heavy(aug, gamma1)
    if numpy and solver == "SCS" and (found := _numpy_gamma_min(aug, sigma, gamma1)) is not None:
        return found
    g, status = _bound(aug, sigma, None, gamma1, solver,
                       lambda g2, tau, sy, p: -sy * _d_size(aug) * math.sqrt(max(g2, p["gamma1"] ** 2)))  # fmt: skip
    if g is None and status not in SOLVED and numpy and solver != "SCS":
        return _numpy_gamma_min(aug, sigma, gamma1) or (None, status)
    return (None if g is None else float(-g)), status


@_memo
def sigma_max(aug: Augmented, gamma: float | None, gamma1: float, solver: str) -> tuple[float | None, str]:
    """The largest sigma with (45) feasible at ``gamma`` (None: gamma infinite), and the status.

    None when (45) is infeasible even at sigma -> 0 (then no sigma helps: gamma must rise)."""
    numpy = gamma is not None and _heavy(aug, gamma1)
    if numpy and solver == "SCS" and (found := _numpy_sigma_max(aug, gamma, gamma1)) is not None:
        return found
    # back to the plant's units (gamma sy, sigma / (tau sy)^2)
    s, status = _bound(aug, None, gamma, gamma1, solver, lambda q, tau, sy, p: q / (tau * sy) ** 2)
    if s is None and status not in SOLVED and numpy and solver != "SCS":
        return _numpy_sigma_max(aug, gamma, gamma1) or (None, status)
    return (float(s) if s is not None and s > 0 else None), status


@dataclass(frozen=True)
class FrontierPoint:
    """One sigma of the frontier: the smallest feasible gamma, and the design tried just above it."""

    sigma: float
    gamma_min: float | None
    gamma_tried: float | None
    certified: bool
    alpha: float | None
    max_abs_L1: float | None
    note: str = ""
    #: the certified design's largest stable sample time (eigenvalues of I + Ts R_i), None without one
    ts_max: float | None = None


def reach_max(aug: Augmented, params: dict, headroom, half_width, solver: str) -> tuple[float | None, str]:
    """The largest reach within the input limits any common gain allows under (45) at ``params`` (and the LMI
    'decay' at ``params["beta"]`` where the design asked a rate): ``max rho`` over ``X, Y`` (one gain
    ``K = Su Y X^-1``, (45) at sigma, gamma, gamma1) such that on the level set
    ``x' X^-1 x <= 1`` every input stays within its ``headroom`` (``[[h_i^2, (Su Y)_i], [(Su Y)_i', X]] >= 0``) and
    that set reaches ``rho`` times ``half_width`` along each state with a finite one (``X_kk >= rho^2 w_k^2``).
    (45) is posed homogeneous (``const = s``, an unknown scale: the level set is any level), so a design's own
    reach (:func:`fte_casadi.design._recertify.unsaturated`'s ``fraction``) is a feasible point: the answer is
    at least it. ``(rho, status)``; ``(None, status)`` where the solver finds no answer."""
    n, m = aug.n, aug.m
    Su = input_scaling(aug)
    sg, g, g1 = params["sigma"], params["gamma"], params["gamma1"]
    h = np.asarray(headroom, dtype=float)
    w = np.asarray([np.nan if v is None else v for v in half_width], dtype=float)
    ok = np.flatnonzero(np.isfinite(w) & (w > 0))
    if not len(ok) or np.any(h <= 0):
        return (0.0 if np.any(h <= 0) else None), "no bound"
    layout = Layout(Var("X", (n, n), True), Var("Y", (m, n)), Var("s", ()), Var("q", ()))
    lmis = [affine_lmi(f"(45) rule {i + 1}", layout, lambda X, Y, s, q, i=i: lmi45(aug, i, X, Su @ Y, sg, g, g1, const=s),
                       kron=("X", lmi45_kron(aug, i)))
            for i in range(aug.r)]  # fmt: skip
    beta = float(params.get("beta") or 0.0)
    if beta > 0:  # the loop's decay rate the design asked (and its X certifies): homogeneous in X, Y
        lmis += [affine_lmi(f"decay rule {i + 1}", layout, lambda X, Y, s, q, i=i: lmi_decay(aug, i, X, Su @ Y, beta),
                            kron=("X", lmi_decay_kron(aug, i, beta)))
                 for i in range(aug.r)]  # fmt: skip
    for i in range(m):

        def inp(X, Y, s, q, i=i):
            row = (Su @ Y)[i : i + 1]
            return -np.block([[np.array([[h[i] ** 2]]), row], [row.T, X]])

        lmis.append(affine_lmi(f"input {i + 1}", layout, inp))
    lmis.append(affine_lmi("reach", layout, lambda X, Y, s, q: np.diag(q * w[ok] ** 2 - np.diag(X)[ok])))
    lmis.append(affine_lmi("s >= 0", layout, lambda X, Y, s, q: -np.array([[s]])))
    c = np.zeros(layout.size)
    c[layout.index("q")] = -1.0
    res = ConicProblem(layout, lmis, c).solve(solver)
    if res.v is None or res.status not in SOLVED:
        return None, res.status
    q = float(layout.unpack(res.v)["q"])
    return math.sqrt(max(q, 0.0)), res.status
