"""Checks of the automatic sector method: singular terms, exactness, readable texts.

:func:`check_term` refuses, before any derivation, a term whose coefficients would be unbounded on
the region: a denominator, a ``tan``, ``log``, ``sqrt``, power, ``atanh``, ``asin``/``acos`` whose
argument reaches its singularity there (the argument's range comes from the global bound search).
:func:`check_exact` is the proof afterwards: the blended T-S model must equal the plain equations
to round-off at the fidelity samples, along the fidelity trajectory, and at points where a state is
0 or tiny (where the removable singularities were filled); otherwise the derivation is refused with
the row and the point where it is wrong.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .._text import shorten
from ..errors import BoundsError, DerivationError
from ..model import Plant
from ._fidelity import blended, sample_box
from ._premise_bounds import premise_bounds

__all__ = ["check_term", "check_exact", "expr_text", "EXACT_TOL", "TAYLOR_BAND", "state_scale"]

#: an automatic sector model must match the plain equations to this, relative to each row's largest value
EXACT_TOL = 1e-9
#: the automatic method replaces the quotient of a smooth term by its Taylor expansion where |x_j| < TAYLOR_BAND
#: x the state's scale on the region (:func:`state_scale`; :mod:`._auto`)
TAYLOR_BAND = 1e-4
#: state values at which exactness is checked besides the random samples (the filled singularities and both
#: sides of the Taylor band's edge), in units of each state's scale (0 and 1e-300 as they are)
_NEAR_ZERO = (0.0, 1e-300, 1e-12, 1e-8, TAYLOR_BAND * (1 - 1e-9), TAYLOR_BAND * (1 + 1e-9), 1e-3)


def state_scale(lo: float, hi: float) -> float:
    """The size of a state on its region, ``max(|lo|, |hi|)``: what the automatic method's tolerances about
    ``x_j = 0`` are relative to (1 for a state without bounds, or on the region [0, 0])."""
    s = max(abs(lo), abs(hi)) if np.isfinite(lo) and np.isfinite(hi) else 1.0
    return float(s) if s > 0 else 1.0


def expr_text(e: ca.SX, limit: int = 160) -> str:
    """A readable one-line text of a scalar expression (no ``@1=`` shared-subexpression notation)."""
    memo: dict[int, str] = {}

    def rec(v: ca.SX) -> str:
        key = v.element_hash()
        if key not in memo:
            if v.is_symbolic():
                memo[key] = v.name()
            elif v.is_constant():
                memo[key] = f"{float(ca.DM(v)):.6g}"
            elif v.is_op(ca.OP_SQ):
                a = rec(v.dep(0))
                memo[key] = f"{a}^2" if _atomic(a) else f"({a})^2"
            elif v.is_op(ca.OP_INV):  # CasADi prints (1./a)
                a = rec(v.dep(0))
                memo[key] = f"(1/{a})" if _atomic(a) else f"(1/({a}))"
            else:
                args = [rec(v.dep(i)) for i in range(v.n_dep())]
                if ca.print_operator(v, ["ARG"] * len(args)).endswith(
                    "(" + ",".join(["ARG"] * len(args)) + ")"
                ):
                    args = [_strip(a) for a in args]  # a function call: sin(-x1), not sin((-x1))
                memo[key] = ca.print_operator(v, args)
        return memo[key]

    return shorten(_strip(rec(e)), limit)


def _atomic(s: str) -> bool:
    """A name, a number, a function call or a parenthesised expression: no parentheses needed."""
    return s.replace(".", "").replace("_", "a").isalnum() or (
        s.endswith(")") and _balanced(s[s.index("(") + 1 : -1])
    )


def _strip(s: str) -> str:
    """``s`` without one pair of enclosing parentheses, when they enclose all of it."""
    return s[1:-1] if s.startswith("(") and s.endswith(")") and _balanced(s[1:-1]) else s


def _balanced(s: str) -> bool:
    depth = 0
    for ch in s:
        depth += {"(": 1, ")": -1}.get(ch, 0)
        if depth < 0:
            return False
    return depth == 0


def _singular_args(h: ca.SX):
    """``(operation, argument, test)`` for every operation of ``h`` that has a singularity."""
    seen, stack = set(), [h]
    while stack:
        v = stack.pop()
        if v.is_leaf() or v.element_hash() in seen:
            continue
        seen.add(v.element_hash())
        stack += [v.dep(i) for i in range(v.n_dep())]
        if v.is_op(ca.OP_INV):
            yield "division", v.dep(0), lambda mn, mx: mn <= 0 <= mx, "is 0"
        elif v.is_op(ca.OP_DIV):
            yield "division", v.dep(1), lambda mn, mx: mn <= 0 <= mx, "is 0"
        elif v.is_op(ca.OP_TAN):
            yield "tan", v.dep(0), _tan_pole, "reaches pi/2 + k pi"
        elif v.is_op(ca.OP_LOG):
            yield "log", v.dep(0), lambda mn, mx: mn <= 0, "is not positive"
        elif v.is_op(ca.OP_LOG1P):
            yield "log1p", v.dep(0), lambda mn, mx: mn <= -1, "is not above -1"
        elif v.is_op(ca.OP_SQRT):
            yield "sqrt", v.dep(0), lambda mn, mx: mn < 0, "is negative"
        elif v.is_op(ca.OP_ATANH):
            yield "atanh", v.dep(0), lambda mn, mx: max(-mn, mx) >= 1, "reaches +-1"
        elif v.is_op(ca.OP_ASIN) or v.is_op(ca.OP_ACOS):
            yield "asin/acos", v.dep(0), lambda mn, mx: max(-mn, mx) > 1, "leaves [-1, 1]"
        elif (v.is_op(ca.OP_POW) or v.is_op(ca.OP_CONSTPOW)) and v.dep(1).is_constant():
            k = float(ca.DM(v.dep(1)))
            if k < 0:
                yield "negative power", v.dep(0), lambda mn, mx: mn <= 0 <= mx, "is 0"
            elif k != int(k):
                yield "fractional power", v.dep(0), lambda mn, mx: mn < 0, "is negative"


def _tan_pole(mn: float, mx: float) -> bool:
    return np.ceil((mn - np.pi / 2) / np.pi) <= np.floor((mx - np.pi / 2) / np.pi)


def check_term(h: ca.SX, plant: Plant, where: str) -> None:
    """Refuse a term with a singularity on the region, naming it and the argument's range."""
    x = plant.x
    others = ca.vertcat(plant.u, plant.d, plant.f, plant.d2)
    for op, arg, bad, what in _singular_args(h):
        if not ca.depends_on(arg, x) or (others.numel() and ca.depends_on(arg, others)):
            continue
        idx = [j for j in range(plant.n) if ca.depends_on(arg, x[j])]
        if any(np.isnan(plant.region_lo[j]) for j in idx):
            continue  # a coefficient on an unbounded state is refused later, with its own message
        text = expr_text(arg, 80)
        try:
            mn, mx, _, _ = premise_bounds(text, arg, x, plant.region_lo, plant.region_hi, plant.state_names,
                                          allow_constant=True)  # fmt: skip
        except BoundsError as exc:
            raise DerivationError(
                f"{where} is not finite {('at ' + exc.where) if exc.where else 'on the region'} (its {op} argument "
                f"{text}); narrow the region (b.region) or rewrite the term"
            ) from None
        if bad(mn, mx):
            states = ", ".join(plant.state_names[j] for j in idx)
            real = op in ("division", "tan", "negative power")  # a pole; the others leave their domain
            raise DerivationError(
                f"{where} is {'unbounded' if real else 'not real'} on the region: the argument {text} of its {op} "
                f"{what} there (it ranges over [{mn:.6g}, {mx:.6g}] for {states} in the region). "
                + ("Its coefficients cannot be bounded: narrow" if real else "Narrow")
                + " the region (b.region) to keep away from the singularity, or rewrite the term"
            )


def _plain(plant: Plant, s: dict):
    """The plain drift and diffusion at the sample columns ``s``."""
    N = s["x"].shape[1]
    tf = np.array(plant.drift_function().map(N)(s["x"], s["u"], s["d"], s["f"]))
    tg = np.array(plant.diffusion_function().map(N)(s["x"], s["u"], s["f"], s["d2"]))
    return tf, tg


def _plain_and_blended(plant: Plant, ts, s: dict, plain=None):
    """The plain drift and diffusion at the sample columns ``s`` (``plain`` when already known), and the blended
    T-S model's."""
    tf, tg = _plain(plant, s) if plain is None else plain
    bf, bg = blended(ts, s["x"], s["u"], s["d"], s["f"], s["d2"])
    return tf, tg, bf, bg


def _row_scales(tf: np.ndarray, tg: np.ndarray) -> np.ndarray:
    """Per state, the largest finite |drift| or |diffusion| of its row over the samples: what that row's error
    is measured against. A row is in its state's unit (per second, or per root second), so the test does
    not change when a state is written in other units (a gap in m or in mm)."""
    both = np.abs(np.hstack([tf, tg]))
    both[~np.isfinite(both)] = 0.0
    return np.max(both, axis=1, initial=0.0)


def _worst(plant: Plant, x: np.ndarray, values, scales: np.ndarray):
    """``(error over its row's scale, error, row text, x, row scale)`` of the largest such ratio at the sample
    columns ``x``, ``values`` the plain and blended values there (:func:`_plain_and_blended`)."""
    tf, tg, bf, bg = values
    best = (0.0, 0.0, "", None, 0.0)
    for kind, t, b in (("drift", tf, bf), ("diffusion", tg, bg)):
        e = np.abs(t - b)
        e[~np.isfinite(e)] = np.inf
        with np.errstate(divide="ignore", invalid="ignore"):
            rel = np.where(e == 0, 0.0, e / scales[:, None])
        i, k = np.unravel_index(int(np.argmax(rel)), rel.shape)
        if rel[i, k] > best[0]:
            best = (float(rel[i, k]), float(e[i, k]), f"{kind} row {plant.state_names[i]!r}", x[:, k],
                    float(scales[i]))  # fmt: skip
    return best


def check_exact(ts, seed: int = 0) -> None:
    """Refuse an automatic sector model that is not exact to round-off (see the module docstring).

    Each row's error is measured against that row's largest value over the fidelity samples (drift or
    diffusion, :func:`_row_scales`): exact to :data:`EXACT_TOL` of it, in whatever units the state is written.
    The fidelity samples and trajectory are those of ``ts.fidelity`` (drawn again, with the same seed); the
    points near 0 (and about the edge of the Taylor band, in each state's scale) are drawn here.
    """
    plant = ts.plant
    fid = ts.fidelity
    rng = np.random.default_rng(seed)
    s = sample_box(plant, max(fid.samples, 1), rng)  # the fidelity's samples (same seed, same draw)
    base = sample_box(plant, 32, rng)
    near = {k: [] for k in base}
    lo, hi = plant.region_lo, plant.region_hi
    for j in range(plant.n):
        sj = state_scale(lo[j], hi[j])
        for v in _NEAR_ZERO:
            v = v if v <= 1e-300 else v * sj
            for sv in (v, -v) if v else (v,):
                if np.isnan(lo[j]) or lo[j] <= sv <= hi[j]:
                    for k in base:
                        near[k].append(base[k].copy())
                    near["x"][-1][j] = sv
    plain = _plain(plant, s)
    scales = _row_scales(*plain)
    worst = (0.0, 0.0, "", None, 0.0)
    if fid.max_abs_error > EXACT_TOL * float(np.min(scales, initial=0.0)):  # some row may fail: find it
        worst = _worst(plant, s["x"], _plain_and_blended(plant, ts, s, plain), scales)
    if near["x"]:
        at = {k: np.concatenate(v, axis=1) for k, v in near.items()}
        found = _worst(plant, at["x"], _plain_and_blended(plant, ts, at), scales)
        worst = found if found[0] > worst[0] else worst
    # the trajectory's error is one number over all rows: against the largest row's scale
    traj = fid.trajectory_max_abs_error
    top = float(np.max(scales, initial=0.0))
    if worst[0] <= EXACT_TOL and (traj == 0.0 or traj <= EXACT_TOL * top):
        return
    if worst[0] > EXACT_TOL:
        at = ", ".join(f"{nm} = {v:.6g}" for nm, v in zip(plant.state_names, worst[3]))
        what = f"{worst[2]} differs from the plain equations by {worst[1]:.3g} at {at}"
        scale = worst[4]
    else:
        what = f"it differs from the plain equations by {traj:.3g} along the fidelity trajectory"
        scale = top
    premises = "; ".join(f"{p.name} = {p.expr} in [{p.min:.6g}, {p.max:.6g}]" for p in ts.premises) or "none"
    raise DerivationError(
        f"the automatic sector model is not exact: {what} (allowed: {EXACT_TOL:g} x {scale:.3g}, the row's largest "
        f"value over the region; premises: {premises}). A term with a jump, or whose coefficients grow without "
        "bound on the region, cannot be written with bounded premises: rewrite it, narrow the region, declare "
        "premises yourself (b.premise), or linearise at operating points (b.operating_points)"
    )
