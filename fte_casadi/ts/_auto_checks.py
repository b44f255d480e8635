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

from ..errors import BoundsError, DerivationError
from ..model import Plant
from ._bounds import premise_bounds
from ._fidelity import blended, sample_box

__all__ = ["check_term", "check_exact", "expr_text", "EXACT_TOL"]

#: an automatic sector model must match the plain equations to this, relative to max(1, |drift|)
EXACT_TOL = 1e-9
#: state values at which exactness is checked besides the random samples (the filled singularities)
_NEAR_ZERO = (0.0, 1e-300, 1e-12, 1e-8, 1e-4 * (1 - 1e-9), 1e-4 * (1 + 1e-9), 1e-3)


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

    s = _strip(rec(e))
    return s if len(s) <= limit else s[: limit - 3] + "..."


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


def _worst(plant: Plant, ts, s: dict, scale: float):
    """``(error, row text, x)`` of the largest error at the sample columns ``s``."""
    N = s["x"].shape[1]
    tf = np.array(plant.drift_function().map(N)(s["x"], s["u"], s["d"], s["f"]))
    tg = np.array(plant.diffusion_function().map(N)(s["x"], s["u"], s["f"], s["d2"]))
    bf, bg = blended(ts, s["x"], s["u"], s["d"], s["f"], s["d2"])
    ef, eg = np.abs(tf - bf), np.abs(tg - bg)
    ef[~np.isfinite(ef)] = np.inf
    eg[~np.isfinite(eg)] = np.inf
    e, kind = (ef, "drift") if np.max(ef) >= np.max(eg) else (eg, "diffusion")
    i, k = np.unravel_index(int(np.argmax(e)), e.shape)
    finite = np.abs(tf[np.isfinite(tf)])
    return (
        float(e[i, k]),
        f"{kind} row {plant.state_names[i]!r}",
        s["x"][:, k],
        float(np.max(finite, initial=scale)),
    )


def check_exact(ts, seed: int = 0) -> None:
    """Refuse an automatic sector model that is not exact to round-off (see the module docstring).

    The fidelity samples and trajectory are those of ``ts.fidelity`` (drawn again, with the same
    seed, only to locate an error); the points near 0 are drawn here.
    """
    plant = ts.plant
    fid = ts.fidelity
    rng = np.random.default_rng(seed)
    s = sample_box(plant, max(fid.samples, 1), rng)  # the fidelity's samples (same seed, same draw)
    base = sample_box(plant, 32, rng)
    near = {k: [] for k in base}
    lo, hi = plant.region_lo, plant.region_hi
    for j in range(plant.n):
        for v in _NEAR_ZERO:
            for sv in (v, -v) if v else (v,):
                if np.isnan(lo[j]) or lo[j] <= sv <= hi[j]:
                    for k in base:
                        near[k].append(base[k].copy())
                    near["x"][-1][j] = sv
    scale = max(
        1.0, fid.drift_max_abs_error / fid.drift_max_rel_error if fid.drift_max_rel_error > 0 else 1.0
    )
    worst = (0.0, "", None)
    if near["x"]:
        worst = _worst(plant, ts, {k: np.concatenate(v, axis=1) for k, v in near.items()}, scale)[:3]
    tol = EXACT_TOL * scale
    if fid.max_abs_error > tol:  # locate it among the fidelity's samples
        found = _worst(plant, ts, s, scale)[:3]
        worst = found if found[0] > worst[0] else worst
    traj = fid.trajectory_max_abs_error
    if worst[0] <= tol and fid.max_abs_error <= tol and traj <= tol:
        return
    if worst[0] > tol:
        at = ", ".join(f"{nm} = {v:.6g}" for nm, v in zip(plant.state_names, worst[2]))
        what = f"{worst[1]} differs from the plain equations by {worst[0]:.3g} at {at}"
    else:
        what = f"it differs from the plain equations by {traj:.3g} along the fidelity trajectory"
    premises = "; ".join(f"{p.name} = {p.expr} in [{p.min:.6g}, {p.max:.6g}]" for p in ts.premises) or "none"
    raise DerivationError(
        f"the automatic sector model is not exact: {what} (allowed: {EXACT_TOL:g} x {scale:.3g}; premises: "
        f"{premises}). A term with a jump, or whose coefficients grow without bound on the region, cannot be "
        "written with bounded premises: rewrite it, narrow the region, declare premises yourself (b.premise), or "
        "linearise at operating points (b.operating_points)"
    )
