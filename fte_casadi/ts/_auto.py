"""Automatic sector nonlinearity: premises found in the plain nonlinear equations.

A plant that declares no premise (and no operating points) is written with its plain
nonlinearities (``-3.33 * sin(theta_l)``, ``x1 * x2``, ``tanh(x1)``). This module rewrites it
exactly in the form the sector method needs, ``f = A(z) x + B(z) u + Bd(z) d + Bf(z) f + a`` and
``g = W(z) x + G(z) u + Gf(z) f + M(z) d2``, with premises ``z(x)``:

1. Each row is split into additive terms (through sums, differences, negations and constant
   factors of CasADi's expression tree). A term must be affine in u, d, f (d2 in the diffusion);
   their coefficients may depend on x. A term that is singular on the region (a denominator,
   ``tan``, ``log``... reaching its pole there) is refused by name (:mod:`._auto_checks`).
2. The x-part ``h(x)`` of a term is telescoped along the states it uses, in state order:
   ``h(x) = h(0) + sum_j c_j(x) x_j`` with ``c_j = [h(x1..xj, 0..) - h(x1..x(j-1), 0..)] / xj``,
   an exact identity, built symbolically (nothing is sampled). When the difference has ``xj`` as
   a factor (``x1 * x2``, ``x1**3``) the factor is divided out and there is no singularity.
   Otherwise ``c_j`` has a removable singularity at ``xj = 0``, where its value is the partial
   derivative ``dh/dxj``. For a smooth term the quotient is replaced, where ``|xj| <``
   :data:`TAYLOR_BAND` ``x s_j``, by its Taylor expansion ``d1 + d2 xj/2 + d3 xj^2/6`` (exact at 0):
   the quotient itself loses ``eps |h| / |xj|`` to cancellation near 0 (measured: ``(exp(x) - 1)/x``
   is wrong by 1.0 at ``x = 1e-17`` with a fill at 0 only; with the band the coefficient of a
   unit-scale term is within 7e-13 of its exact value everywhere, of ``sin(100 x)`` within 8e-11,
   and the product ``c_j xj`` always at round-off). ``s_j`` is the state's scale on the region,
   ``max(|lo_j|, |hi_j|)`` (:func:`state_scale`): both errors depend on ``xj`` relative to the
   length over which ``h`` varies, so a band in the state's own size gives the same coefficient
   whatever unit the state is written in (a gap in m or in mm), and the band of a state on [-1, 1]
   is ``TAYLOR_BAND`` itself. A term with a kink (``fabs``, ``fmin``,
   ``if_else``...) may have a different slope on each side of 0: it keeps the exact quotient and
   is filled at ``xj = 0`` only.
3. Every coefficient that is not constant is a premise candidate. Candidates that are affine
   functions of one another (``c = alpha + beta g(x)``, tested at 64 random points of the
   region to 1e-9 of the coefficient's own size, then used symbolically) share one premise ``g``: the manipulator's ``sin(theta_l)``
   in drift and diffusion gives one premise and the paper's two rules.
4. Normalisation and orientation. A premise is the coefficient of the first candidate of its
   group, in row order (drift before diffusion) and then column order, neither shifted nor
   scaled (memberships do not change under a positive affine change of the premise, so the
   coefficient itself is the most readable choice). Its sign is chosen so that its value at the
   anchor of the decomposition, the origin (projected onto the region), lies in the upper half
   of its range; when it lies exactly at the middle the written sign is kept. With the documented
   rule order (docs/interface.md: rule 1 at each premise's max) rule 1 is the rule closest to the origin, the
   point about which the sector model is built, and the order does not depend on how a sign was
   written (``3.33 * sin(-theta)`` gives the same rules as ``-3.33 * sin(theta)``). For the
   manipulator the premise is ``sin(theta_l)/theta_l``, 1 at the origin: rule 1 at 1, rule 2 at
   its minimum -0.2172, as in the paper.

The result is a plant written with premise symbols, which the ordinary sector method derives
with the bounds found here; :func:`~fte_casadi.ts.derive` then checks it against the plain
equations and refuses it unless it is exact to round-off (:func:`._auto_checks.check_exact`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
import warnings

import casadi as ca
import numpy as np

from ..errors import BoundsError, DerivationError
from ..model import Plant
from ._auto_checks import TAYLOR_BAND, check_term, expr_text, state_scale
from ._cover import estimate_rules, plan_groups
from ._premise_bounds import premise_bounds

__all__ = ["premise_form", "PremiseForm", "WARN_PREMISES", "MAX_PREMISES", "TAYLOR_BAND", "state_scale"]

#: above this many premises (64 rules) derive warns; above MAX_PREMISES it refuses
WARN_PREMISES = 6
MAX_PREMISES = 10
#: local searches per bound of a premise (the bound is widened by what could not be searched, and says so)
SEARCHES = 200
#: the orders of the states tried for the telescoping (all of them up to 6 states in shared terms)
MAX_ORDERS = 720
#: a coefficient whose range over the region is within this fraction of its size is a constant written with
#: round-off, not a premise (a CSTR's k(T*) (Ca* + c) - r* over c, with r* = k(T*) Ca* computed apart, spans 6e-12
#: of itself: 4 rules where 2 are exact); a hundredth of the exactness allowance EXACT_TOL, which
#: :func:`._auto_checks.check_exact` checks on the model that takes it as its constant
CONSTANT_SPREAD = 1e-11
#: a constant offset within this x the sum of the sizes of the constants it adds up is round-off: 0
ROUNDOFF_SUM = 16 * np.finfo(float).eps
#: operations with a kink or a jump: such a term keeps its exact quotient (filled at 0 only)
_NONSMOOTH = {getattr(ca, k) for k in ("OP_FABS", "OP_SIGN", "OP_FLOOR", "OP_CEIL", "OP_FMOD", "OP_FMIN",
              "OP_FMAX", "OP_IF_ELSE_ZERO", "OP_LT", "OP_LE", "OP_EQ", "OP_NE", "OP_NOT", "OP_AND", "OP_OR",
              "OP_COPYSIGN", "OP_REMAINDER") if hasattr(ca, k)}  # fmt: skip


@dataclasses.dataclass(frozen=True)
class PremiseForm:
    """The plant rewritten with automatic premises ``z1..zq``, their bounds, and notes for reports."""

    plant: Plant
    #: per premise ``(min, max, states, gap)``, as :func:`~fte_casadi.ts._premise_bounds.premise_bounds` returns
    bounds: tuple[tuple[float, float, tuple[int, ...], float], ...]
    notes: tuple[str, ...]


@dataclasses.dataclass(frozen=True)
class _Piece:
    """One coefficient contributed by one term: ``factor * expr`` enters ``matrix[row, col]``."""

    matrix: str
    row: int
    col: int
    factor: float
    expr: ca.SX
    text: str  # "" when the coefficient is a constant
    where: str  # e.g. "drift row 'w_l', the coefficient of 'theta_l' in the term -3.33*sin(theta_l)"
    #: (drift 0 / diffusion 1, row, term, inputs 0 / states 1): pieces are taken in this order
    seq: tuple = (0, 0, 0, 0)


def _terms(e: ca.SX, scale: float = 1.0) -> list[tuple[float, ca.SX]]:
    """Additive terms ``(factor, expression)`` of a scalar expression (constants as ``(value, 1)``)."""
    if e.is_constant():
        return [(scale * float(ca.DM(e)), ca.SX(1.0))]
    if e.is_op(ca.OP_ADD):
        return _terms(e.dep(0), scale) + _terms(e.dep(1), scale)
    if e.is_op(ca.OP_SUB):
        return _terms(e.dep(0), scale) + _terms(e.dep(1), -scale)
    if e.is_op(ca.OP_NEG):
        return _terms(e.dep(0), -scale)
    if e.is_op(ca.OP_TWICE):
        return _terms(e.dep(0), 2.0 * scale)
    if e.is_op(ca.OP_MUL):
        a, b = e.dep(0), e.dep(1)
        if a.is_constant():
            return _terms(b, scale * float(ca.DM(a)))
        if b.is_constant():
            return _terms(a, scale * float(ca.DM(b)))
    if e.is_op(ca.OP_DIV) and e.dep(1).is_constant():
        return _terms(e.dep(0), scale / float(ca.DM(e.dep(1))))
    return [(scale, e)]


def _smooth(e: ca.SX) -> bool:
    """True when no operation of ``e`` has a kink or a jump."""
    seen, stack = set(), [e]
    while stack:
        v = stack.pop()
        if v.element_hash() in seen or v.is_leaf():
            continue
        seen.add(v.element_hash())
        if v.op() in _NONSMOOTH:
            return False
        stack += [v.dep(i) for i in range(v.n_dep())]
    return True


def _divide(h: ca.SX, xj: ca.SX) -> ca.SX | None:
    """``h / xj`` when ``xj`` is a factor of ``h`` (products, squares, integer powers), else None."""
    if ca.is_equal(h, xj):
        return ca.SX(1.0)
    if h.is_op(ca.OP_SQ) and ca.is_equal(h.dep(0), xj):
        return xj
    if h.is_op(ca.OP_NEG):
        q = _divide(h.dep(0), xj)
        return None if q is None else -q
    if h.is_op(ca.OP_MUL):
        a, b = h.dep(0), h.dep(1)
        q = _divide(a, xj)
        if q is not None:
            return q * b
        q = _divide(b, xj)
        return None if q is None else a * q
    if h.is_op(ca.OP_DIV):
        q = _divide(h.dep(0), xj)
        return None if q is None else q / h.dep(1)
    if h.is_op(ca.OP_CONSTPOW) and ca.is_equal(h.dep(0), xj) and h.dep(1).is_constant():
        k = float(ca.DM(h.dep(1)))
        return xj ** (k - 1) if k >= 1 and k == int(k) else None
    return None


def _coefficient(
    h: ca.SX, x: ca.SX, j: int, smooth: bool, later=None, band: float = TAYLOR_BAND
) -> tuple[ca.SX, str]:
    """``(c_j, text)``: ``[h(.., xj, 0..) - h(.., 0, 0..)] / xj``, its singularity at ``xj = 0`` filled.

    ``later``: the states telescoped after ``xj`` (set to 0 in both values); by default those after it
    in the plant's order. ``band``: where ``|xj| < band`` a smooth term's quotient is replaced by its
    Taylor expansion (``TAYLOR_BAND`` x the state's scale)."""
    n = x.numel()
    xj = x[j]
    later = list(range(j + 1, n)) if later is None else list(later)
    upto = ca.substitute(h, ca.vertcat(*[x[k] for k in later]), ca.DM.zeros(len(later))) if later else h
    if not ca.depends_on(upto, xj):
        return ca.SX(0.0), ""
    below = ca.substitute(upto, xj, ca.DM(0.0))
    exact = _divide(upto, xj) if below.is_zero() else None
    q = exact if exact is not None else ca.simplify((upto - below) / xj)
    if exact is not None or not ca.depends_on(q, xj):  # no singularity left (x1 x2 / x2 = x1)
        return q, expr_text(q)
    d1 = ca.jacobian(upto, xj)
    if not smooth:
        return (
            ca.if_else(xj == 0, ca.substitute(d1, xj, ca.DM(0.0)), guarded(q, xj, xj == 0, band)),
            expr_text(q),
        )
    d2 = ca.jacobian(d1, xj)
    d3 = ca.jacobian(d2, xj)
    t1, t2, t3 = (ca.substitute(v, xj, ca.DM(0.0)) for v in (d1, d2, d3))
    taylor = t1 + t2 * xj / 2 + t3 * xj**2 / 6
    near = ca.fabs(xj) < band
    return ca.if_else(near, taylor, guarded(q, xj, near, band)), expr_text(q)


def guarded(q: ca.SX, xj: ca.SX, near: ca.SX, band: float = TAYLOR_BAND) -> ca.SX:
    """``q`` with ``xj`` moved to ``band`` where ``near`` holds: the branch ``if_else`` discards.

    An ``SX`` ``if_else`` evaluates both branches (so does the C CasADi generates from it) and then
    keeps one; the quotient ``q = [h(xj) - h(0)] / xj`` evaluated at ``xj = 0`` is ``0/0`` there, a NaN
    that is thrown away but raises ``FE_INVALID`` (a trap, with floating-point exceptions enabled).
    Evaluated at ``band`` instead it is finite, and where the quotient is kept (``near`` false)
    ``xj`` is itself: ``if_else`` adds ``0 + xj``, exact, so the numbers do not change.
    """
    return ca.substitute(q, xj, ca.if_else(near, band, xj))


def _value(e: ca.SX) -> float:
    return float(ca.DM(ca.evalf(e)))


@dataclasses.dataclass(frozen=True)
class _Term:
    """The x-part ``h0`` of one additive term of a row (inputs set to 0), to be telescoped."""

    kind: str  # "drift" or "diffusion"
    row: int
    factor: float
    h0: ca.SX
    smooth: bool
    states: tuple[int, ...]
    where: str  # "drift row 'w_l'"
    text: str
    seq: tuple


def _split(plant: Plant, kind: str) -> tuple[list[_Piece], list[_Term], np.ndarray]:
    """Coefficient pieces of the inputs of the drift or the diffusion, its terms in x (telescoped by
    :func:`_state_pieces` along an order of the states), and its constant offset (an entry within round-off
    of the constant terms it sums, ``ROUNDOFF_SUM`` x their sizes, is 0: ``g - k i0^2 / (m x0^2)`` at the
    operating point cancels to 0 in m and to -1.8e-12 in mm)."""
    x = plant.x
    if kind == "drift":
        rows = plant.drift_z
        vars_ = (("B", plant.u, plant.input_names), ("Bd", plant.d, plant.unknown_input_names),
                 ("Bf", plant.f, plant.fault_names))  # fmt: skip
    else:
        rows = plant.diffusion_z
        vars_ = (("G", plant.u, plant.input_names), ("Gf", plant.f, plant.fault_names),
                 ("M", plant.d2, plant.diffusion_input_names))  # fmt: skip
    others = (
        ca.vertcat(*[v for _, v, _ in vars_ if v.numel()]) if any(v.numel() for _, v, _ in vars_) else None
    )
    pieces, terms, offset, size = [], [], np.zeros(plant.n), np.zeros(plant.n)
    kr = 0 if kind == "drift" else 1
    for i in range(plant.n):
        row = f"{kind} row {plant.state_names[i]!r}"
        for ti, (k, h) in enumerate(_terms(rows[i])):
            term = expr_text(k * h)
            if ca.depends_on(h, x):
                check_term(h, plant, f"{row}: the term {term}")
            for mat, v, vnames in vars_:
                for c in range(v.numel()):
                    b = ca.jacobian(h, v[c])  # affine in u, d, f, d2: checked when the plant was built
                    b = ca.substitute(b, others, ca.DM.zeros(others.numel()))
                    if b.is_zero():
                        continue
                    nonconst = ca.depends_on(b, x)
                    where = f"{row}: the coefficient of {vnames[c]!r} in the term {term}"
                    pieces.append(
                        _Piece(mat, i, c, k, b, expr_text(b) if nonconst else "", where, (kr, i, ti, 0))
                    )
            h0 = ca.substitute(h, others, ca.DM.zeros(others.numel())) if others is not None else h
            if not ca.depends_on(h0, x):
                offset[i] += k * _value(h0)
                size[i] += abs(k * _value(h0))
                continue
            z0 = _value(ca.substitute(h0, x, ca.DM.zeros(plant.n)))
            if not np.isfinite(z0):
                raise DerivationError(
                    f"{row}: the term {term} is not finite at x = 0, the point about which the sector model is "
                    "built, so it cannot be written as bounded coefficients times the states; shift the states so "
                    "that the plant is finite at 0, or declare premises yourself (b.premise)"
                )
            offset[i] += k * z0
            size[i] += abs(k * z0)
            states = tuple(j for j in range(plant.n) if ca.depends_on(h0, x[j]))
            terms.append(_Term(kind, i, k, h0, _smooth(h0), states, row, term, (kr, i, ti, 1)))
    offset[np.abs(offset) <= ROUNDOFF_SUM * size] = 0.0
    return pieces, terms, offset


def _state_pieces(plant: Plant, terms: list[_Term], order, cache: dict) -> list[_Piece]:
    """The coefficient pieces of the states: each term telescoped along ``order`` (a permutation of the
    states; the coefficient of ``x_j`` depends only on which of the term's states come after ``x_j``,
    so ``cache`` keeps each once)."""
    x = plant.x
    pos = {j: k for k, j in enumerate(order)}
    xmat = {"drift": "A", "diffusion": "W"}
    out = []
    for t_i, t in enumerate(terms):
        for j in t.states:
            later = tuple(sorted(k for k in t.states if pos[k] > pos[j]))
            key = (t_i, j, later)
            if key not in cache:
                band = TAYLOR_BAND * state_scale(plant.region_lo[j], plant.region_hi[j])
                c, text = _coefficient(t.h0, x, j, t.smooth, later, band)
                cache[key] = (c, text) if ca.depends_on(c, x) else (ca.SX(_value(c)), "")
            c, text = cache[key]
            where = f"{t.where}: the coefficient of {plant.state_names[j]!r} in the term {t.text}"
            if text or _value(c) != 0.0:
                out.append(_Piece(xmat[t.kind], t.row, j, t.factor, c, text, where, t.seq))
    return out


def _order(plant: Plant, terms: list[_Term], inputs: list[_Piece], rng: np.random.Generator):
    """The order of the states to telescope along, and the state pieces it gives.

    Which state of a product ``x_i x_j`` becomes the premise depends on the order (the earlier one),
    so the plant's own order would decide the rules: ``(i_d, i_q, w)`` of a motor gives the premises
    ``i_d`` and ``i_q``, ``(w, i_d, i_q)`` the single premise ``w``. Every order of the states that
    share a term with another is tried (up to :data:`MAX_ORDERS`), the one with the fewest premises
    kept (then the fewest rules of the grouped cover before groups are merged, :func:`_estimate_rules`; then
    the first by state names), so that the same plant gets the same premises whatever the order its states
    are written in."""
    n = plant.n
    cache: dict = {}
    names = plant.state_names
    mixed = sorted({j for t in terms if len(t.states) > 1 for j in t.states}, key=lambda j: names[j])
    rest = [j for j in range(n) if j not in mixed]
    if len(mixed) < 2:
        order = tuple(range(n))
        return order, _state_pieces(plant, terms, order, cache)
    perms = itertools.permutations(mixed) if math.factorial(len(mixed)) <= MAX_ORDERS else [tuple(mixed)]
    pts = _sample_points(plant, rng)
    best = None
    # per coefficient (the same object in every order that has it), its values; per list of coefficients (many
    # orders give the same list), its score
    values: dict[int, np.ndarray] = {}
    scores: dict[tuple, tuple] = {}
    for perm in perms:  # in the order of the state names: the first best is the same for any plant order
        order = tuple(perm) + tuple(rest)
        pieces = _state_pieces(plant, terms, order, cache)
        cand = [p for p in inputs + pieces if p.text]
        key = tuple(id(p.expr) for p in cand)
        if key not in scores:
            for p in cand:
                if id(p.expr) not in values:
                    fn = ca.Function("c", [plant.x], [p.expr]).map(pts.shape[1])
                    values[id(p.expr)] = np.array(fn(pts)).ravel()
            reps, _, _ = _group(plant, [p.expr for p in cand], None, pts, [values[k] for k in key])
            deps = [frozenset(j for j in range(n) if ca.depends_on(cand[r].expr, plant.x[j])) for r in reps]
            # an order whose coefficients are not finite in the region (a power of a negative number where a later
            # state is set to 0) loses to one whose are; if every order has some, the bounds refuse them by name
            broken = sum(not np.all(np.isfinite(values[k])) for k in key)
            scores[key] = (broken, len(reps), _estimate_rules(deps))
        score = scores[key]
        if best is None or score < best[0]:
            best = (score, order, pieces)
    return best[1], best[2]


def _estimate_rules(deps: list[frozenset]) -> int:
    """Rules of the grouped cover of premises with these state sets, at most: a group per set of states, a
    simplex or a box each, before groups of nested states are merged (:func:`~fte_casadi.ts._cover.plan_groups`
    merges them only above 64 rules, at the price of looser vertices: an order is not chosen for it). A
    quadrotor's kinematics telescoped with the angles first gives premises of the angles alone
    (``sin(phi) tan(theta)``; 108 rules before merging, 48 after), with a rate first premises of three states
    (``cos(phi) tan(theta) r / theta``; 324 before, 32 after but 2.2 times the image's extent away)."""
    return estimate_rules(plan_groups([tuple(sorted(d)) for d in deps], merge=False))


def _sample_points(plant: Plant, rng: np.random.Generator, N: int = 64) -> np.ndarray:
    """``N`` random states of the region (0 for a state without bounds)."""
    lo, hi = plant.region_lo, plant.region_hi
    pts = np.zeros((plant.n, N))
    for j in range(plant.n):
        pts[j] = 0.0 if np.isnan(lo[j]) else lo[j] + (hi[j] - lo[j]) * rng.random(N)
    return pts


def _group(plant: Plant, candidates: list[ca.SX], rng: np.random.Generator | None, pts=None, vals=None):
    """A representative per candidate and ``(alpha, beta)`` with ``c = alpha + beta * rep`` (``vals``: the
    candidates' values at ``pts`` when already known)."""
    pts = _sample_points(plant, rng) if pts is None else pts
    N = pts.shape[1]
    if vals is None and candidates:
        vals = np.array(ca.Function("cands", [plant.x], [ca.vertcat(*candidates)]).map(N)(pts))
    reps, rep_of, coef = [], [], []
    for k in range(len(candidates)):
        v = vals[k]
        found = None
        for r in reps if np.all(np.isfinite(v)) else ():  # a coefficient not finite somewhere is its own
            if not np.all(np.isfinite(vals[r])):
                continue
            A = np.column_stack([np.ones(N), vals[r]])
            ab, *_ = np.linalg.lstsq(A, v, rcond=None)
            if np.all(np.isfinite(ab)) and np.max(np.abs(A @ ab - v)) <= 1e-9 * np.max(np.abs(v)):
                found = (r, float(ab[0]), float(ab[1]))
                break
        if found is None:
            reps.append(k)
            found = (k, 0.0, 1.0)
        rep_of.append(found[0])
        coef.append(found[1:])
    return reps, rep_of, coef


def _bounds(plant: Plant, expr: ca.SX, text: str, where: list[str]):
    """Bounds of a premise candidate, refusals naming the coefficients it stands for."""
    try:
        return premise_bounds(text, expr, plant.x, plant.region_lo, plant.region_hi, plant.state_names,
                              allow_constant=True, max_searches=SEARCHES)  # fmt: skip
    except BoundsError as exc:
        what = "; ".join(where[:3]) + (f" (and {len(where) - 3} more)" if len(where) > 3 else "")
        at = f"at {exc.where}" if exc.where else "on the region"
        raise DerivationError(
            f"{what}: the coefficient {text} is {exc.kind} {at}, so the term cannot be written as bounded "
            "coefficients times the states. Narrow the region (b.region) to keep away from it, shift the states, "
            "or declare premises yourself (b.premise)"
        ) from None


def _orient(plant: Plant, expr: ca.SX, mn: float, mx: float) -> bool:
    """True when the premise must be negated: its value at the origin (projected onto the region) lies
    in the lower half of its range (see the module docstring)."""
    lo = np.where(np.isnan(plant.region_lo), 0.0, plant.region_lo)
    hi = np.where(np.isnan(plant.region_hi), 0.0, plant.region_hi)
    v0 = float(ca.Function("z", [plant.x], [expr])(np.clip(np.zeros(plant.n), lo, hi)))
    return v0 < 0.5 * (mn + mx) - 1e-12 * (mx - mn)


def _origin_outside(plant: Plant, rows: np.ndarray, at_zero: np.ndarray) -> str:
    """For a refusal of additive diffusion in ``rows`` (``at_zero``: its value there at x = 0): where x = 0 lies
    outside the plant's region (states in absolute units, a temperature in K), whether the noise vanishes at the
    reference state (the region's centre without one), with u, f and d2 zero. Where it does, it is proportional to
    the deviation from that point and the plant can be written in deviations; where it does not, it is additive where
    the plant runs too, and deviations do not help (a fluctuating conductance times T1 - To, To outside the region)."""
    lo, hi = plant.region_lo, plant.region_hi
    out = [
        j for j in range(plant.n) if (np.isfinite(lo[j]) and lo[j] > 0) or (np.isfinite(hi[j]) and hi[j] < 0)
    ]
    if not out:
        return ""
    ref = np.asarray(plant.x_ref if plant.x_ref is not None else 0.5 * (lo + hi), dtype=float)
    what = "the reference state" if plant.x_ref is not None else "the region's centre"
    g = plant.diffusion_function()(ref, np.zeros(plant.m), np.zeros(plant.lf), np.zeros(plant.d2.numel()))
    g_ref = np.asarray(g, dtype=float).ravel()[rows]
    more = ", ..." if len(out) > 3 else ""
    shown = ", ".join(f"{plant.state_names[j]} in [{lo[j]:g}, {hi[j]:g}]" for j in out[:3]) + more
    head = f". x = 0 lies outside the plant's region ({shown}): the paper's model is written about x = 0"
    if np.all(np.abs(g_ref) <= ROUNDOFF_SUM * np.maximum(np.abs(at_zero), 1e-300)):
        shifted = ", ".join(f"{plant.state_names[j]} - {ref[j]:g}" for j in out[:3]) + more
        return (
            f"{head}, and the noise vanishes at {what}: write the states as deviations from it ({shifted}; "
            "b.operating_point for the inputs), and it is proportional to them"
        )
    return (
        f"{head}, but the noise does not vanish at {what} either ({g_ref.tolist()} there, with u, f and d2 zero): it is "
        "additive where the plant runs, and writing deviations does not change that. Write the fluctuation as one of a "
        "coefficient times a deviation that vanishes at rest, or leave it out"
    )


def premise_form(plant: Plant, seed: int = 0) -> PremiseForm:
    """The plant rewritten with automatically found premises (see the module docstring).

    A plant without any nonlinear term gets no premise: one rule. Raises
    :class:`~fte_casadi.errors.DerivationError` naming the term that cannot be written so, or
    listing the premises when more than :data:`MAX_PREMISES` would be needed.
    """
    rng = np.random.default_rng(seed)
    inputs_f, terms_f, off_f = _split(plant, "drift")
    inputs_g, terms_g, off_g = _split(plant, "diffusion")
    if np.any(off_g):
        rows = [plant.state_names[i] for i in np.flatnonzero(off_g)]
        raise DerivationError(
            f"the diffusion rows {rows} have a term that is not proportional to x, u, f or d2 (additive noise, "
            f"{off_g[np.flatnonzero(off_g)].tolist()} at x = 0): the paper's model has none; remove it"
            + _origin_outside(plant, np.flatnonzero(off_g), off_g[np.flatnonzero(off_g)])
        )
    order, states = _order(plant, terms_f + terms_g, inputs_f + inputs_g, rng)
    pieces = sorted(inputs_f + inputs_g + states, key=lambda p: p.seq)  # stable: row, term, inputs, states
    cand = [p for p in pieces if p.text]
    _check_bounded(plant, cand)
    reps, rep_of, coef = _group(plant, [p.expr for p in cand], rng)
    texts = [cand[r].text for r in reps]
    if len(reps) > MAX_PREMISES:
        raise DerivationError(
            f"the plant needs {len(reps)} premises ({2 ** len(reps)} rules), more than {MAX_PREMISES}: "
            f"{'; '.join(texts)}. Declare some premises yourself (b.premise) so that terms share them, narrow the "
            "region so that some coefficients become nearly constant, or linearise at operating points instead "
            "(b.operating_points)"
        )
    value, sign, bounds = _premise_bounds(plant, cand, reps, rep_of)
    live = [r for r in reps if r not in value]
    q = len(live)
    names = tuple(f"z{k + 1}" for k in range(q))
    texts = tuple(cand[r].text if sign[r] > 0 else f"-({cand[r].text})" for r in live)
    if q > WARN_PREMISES:
        warnings.warn(
            f"the automatic sector method found {q} premises ({2**q} rules as one box each, fewer where premises "
            f"that depend on the same states are covered together): {'; '.join(texts)}; the design may be slow and "
            "conservative: consider declaring premises yourself, narrowing the region, or linearising",
            RuntimeWarning,
            stacklevel=3,
        )
    z = ca.SX.sym("z", q)
    mats, uses = _matrices(plant, pieces, coef, rep_of, value, sign, live, z)
    x, u, d, f, d2 = plant.x, plant.u, plant.d, plant.f, plant.d2

    def mv(M, v):
        return ca.mtimes(M, v) if v.numel() else ca.SX.zeros(plant.n)

    drift = mv(mats["A"], x) + mv(mats["B"], u) + mv(mats["Bd"], d) + mv(mats["Bf"], f) + ca.DM(off_f)
    diff = mv(mats["W"], x) + mv(mats["G"], u) + mv(mats["Gf"], f) + mv(mats["M"], d2)
    z_exprs = ca.vertcat(*[sign[r] * cand[r].expr for r in live]) if q else ca.SX(0, 1)
    work = dataclasses.replace(plant, z=z if q else ca.SX(0, 1), z_names=names, z_exprs=z_exprs, z_texts=texts,
                               drift_z=drift, diffusion_z=diff)  # fmt: skip
    if q:
        notes = [f"found automatically in the plain equations (sector nonlinearity): {q} premise{'s' * (q > 1)}"
                 f"{f', {2**q} rules' if q == 1 else ''}; each oriented so that rule 1 weighs most at the origin"]  # fmt: skip
        notes += [f"{nm} schedules {', '.join(uses[r])}" for nm, r in zip(names, live)]
    else:
        notes = ["no nonlinear term in the states: one rule (the plant is linear)"]
    if np.any(off_f):
        notes.append(f"constant drift offset a = {np.round(off_f, 6).tolist()} (the same in every rule)")
    return PremiseForm(work, tuple(bounds[r] for r in live), tuple(notes))


def _check_bounded(plant: Plant, cand: list) -> None:
    """Refuse a nonlinear coefficient of a state the region leaves unbounded (its premise would have no range)."""
    for p in cand:
        free = [plant.state_names[j] for j in range(plant.n) if ca.depends_on(p.expr, plant.x[j]) and np.isnan(plant.region_lo[j])]  # fmt: skip
        if free:
            raise DerivationError(
                f"{p.where}: the coefficient {p.text} depends on {free}, which have no bounds: give them with "
                f"b.region({free[0]}=(lower, upper))"
            )


def _premise_bounds(plant: Plant, cand: list, reps: list, rep_of: list) -> tuple[dict, dict, dict]:
    """Per representative coefficient: its value when it is constant over the region after all (``value``), else
    its orientation (``sign``: -1 when rule 1 must weigh most at the other bound) and its oriented bounds
    ``(min, max, where, gap)``."""
    value, sign, bounds = {}, {}, {}
    for r in reps:
        members = [cand[k].where for k in range(len(cand)) if rep_of[k] == r]
        mn, mx, idx, gap = _bounds(plant, cand[r].expr, cand[r].text, members)
        if mx - mn <= CONSTANT_SPREAD * max(abs(mn), abs(mx)):  # relative: a coefficient in any unit
            value[r] = 0.5 * (mn + mx)
            continue
        sign[r] = -1.0 if _orient(plant, cand[r].expr, mn, mx) else 1.0
        bounds[r] = (mn, mx, idx, gap) if sign[r] > 0 else (0.0 - mx, 0.0 - mn, idx, gap)  # no -0.0
    return value, sign, bounds


def _matrices(plant: Plant, pieces: list, coef: list, rep_of: list, value: dict, sign: dict, live: list,
              z: ca.SX) -> tuple[dict, dict]:  # fmt: skip
    """The model's matrices (A, B, Bd, Bf, W, G, Gf, M) with each nonlinear coefficient written in its premise
    (affine in it), and, per live premise, the entries it schedules."""
    mats = {k: ca.SX.zeros(plant.n, dim) for k, dim in (
        ("A", plant.n), ("B", plant.m), ("Bd", plant.ld), ("Bf", plant.lf),
        ("W", plant.n), ("G", plant.m), ("Gf", plant.lf), ("M", plant.d2.numel()))}  # fmt: skip
    uses = {r: [] for r in live}
    ci = 0
    for p in pieces:
        e = p.expr
        if p.text:
            (a, b), r = coef[ci], rep_of[ci]
            e = a + b * value[r] if r in value else a + b * sign[r] * z[live.index(r)]
            ci += 1
            if (
                r in uses
                and f"{p.matrix}[{plant.state_names[p.row]}, {_column_name(plant, p)}]" not in uses[r]
            ):
                uses[r].append(f"{p.matrix}[{plant.state_names[p.row]}, {_column_name(plant, p)}]")
        mats[p.matrix][p.row, p.col] += p.factor * e
    return mats, uses


def _column_name(plant: Plant, p: _Piece) -> str:
    names = {"A": plant.state_names, "W": plant.state_names, "B": plant.input_names, "G": plant.input_names,
             "Bd": plant.unknown_input_names, "Bf": plant.fault_names, "Gf": plant.fault_names,
             "M": plant.diffusion_input_names}  # fmt: skip
    return names[p.matrix][p.col]
