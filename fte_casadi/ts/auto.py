"""Automatic sector nonlinearity: premises found from the plain nonlinear equations.

A plant that declares no premise (and no operating points) is written by the user with its plain
nonlinearities (``-3.33 * sin(theta_l)``, ``x1 * x2``, ``tanh(x1)``). This module rewrites it
exactly in the form the sector method needs, ``f = A(z) x + B(z) u + Bd(z) d + Bf(z) f + a`` and
``g = W(z) x + G(z) u + Gf(z) f + M(z) d2``, with premises ``z(x)``:

1. Each row is split into additive terms (through sums, differences, negations and constant factors
   of CasADi's expression tree). A term must be affine in u, d, f (d2 for the diffusion); its
   coefficients of those may depend on x.
2. The x-part ``h(x)`` of a nonlinear term is telescoped along the states it uses, in state order:
   ``h(x) = h(0) + sum_j c_j(x) x_j``, ``c_j = [h(x1..xj, 0..) - h(x1..x(j-1), 0..)] / xj``, an
   exact identity. Where ``|xj| < 1e-4`` the quotient is replaced by its Taylor expansion to third
   order (exact at ``xj = 0``, where it is the partial derivative, and without the cancellation
   of the quotient near 0). Built symbolically: nothing is sampled.
3. Every coefficient that is not constant is a premise candidate. Candidates that are affine
   functions of one another (``c = alpha + beta g(x)``, tested at 64 random points of the region)
   share one premise ``g``: the manipulator's ``sin(theta_l)`` in drift and diffusion gives one
   premise and the paper's two rules. A premise is the expression of the first candidate of its
   group as written (``sin(theta_l)/theta_l``), not negated or rescaled, so its rule 1 (the premise
   at its maximum, CONTRACT.md's order) is where that expression is largest.

The result is a plant written with premise symbols, which the ordinary sector method derives;
its fidelity is checked against the plain equations, as for any plant.
"""

from __future__ import annotations

import dataclasses
import warnings

import casadi as ca
import numpy as np

from ..errors import DerivationError
from ..model import Plant

__all__ = ["premise_form", "WARN_PREMISES", "MAX_PREMISES", "TAYLOR_BAND"]

#: above this many premises (64 rules) derive warns; above MAX_PREMISES it refuses
WARN_PREMISES = 6
MAX_PREMISES = 10
#: the quotient is replaced by its Taylor expansion where |x_j| < TAYLOR_BAND
TAYLOR_BAND = 1e-4


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


def _quotient(h: ca.SX, x: ca.SX, j: int) -> tuple[ca.SX, ca.SX]:
    """``(c_j, text)``: ``[h(.., xj, 0..) - h(.., 0, 0..)] / xj`` with the Taylor fill near ``xj = 0``."""
    n = x.numel()
    xj = x[j]
    upto = (
        ca.substitute(h, ca.vertcat(*[x[k] for k in range(j + 1, n)]), ca.DM.zeros(n - j - 1))
        if j < n - 1
        else h
    )
    below = ca.substitute(upto, xj, ca.DM(0.0))
    q = ca.simplify((upto - below) / xj)
    if not ca.depends_on(q, xj):  # xj cancels (e.g. (x1 x2)/x2 = x1): no singularity to fill
        return q, q
    d1 = ca.jacobian(upto, xj)
    d2 = ca.jacobian(d1, xj)
    d3 = ca.jacobian(d2, xj)
    at0 = [ca.substitute(v, xj, ca.DM(0.0)) for v in (d1, d2, d3)]
    taylor = at0[0] + at0[1] * xj / 2 + at0[2] * xj**2 / 6
    return ca.if_else(ca.fabs(xj) < TAYLOR_BAND, taylor, q), ca.simplify(q)


def _const(e: ca.SX, syms: ca.SX) -> bool:
    return syms.numel() == 0 or not ca.depends_on(e, syms)


def _split(plant: Plant, kind: str):
    """Coefficient pieces of the drift or diffusion: lists of (matrix, row, col, factor, expr, text)."""
    x = plant.x
    if kind == "drift":
        rows = plant.drift_z
        vars_ = (("B", plant.u, plant.input_names), ("Bd", plant.d, plant.unknown_input_names),
                 ("Bf", plant.f, plant.fault_names))  # fmt: skip
        xmat, what = "A", "drift"
    else:
        rows = plant.diffusion_z
        vars_ = (("G", plant.u, plant.input_names), ("Gf", plant.f, plant.fault_names),
                 ("M", plant.d2, plant.diffusion_input_names))  # fmt: skip
        xmat, what = "W", "diffusion"
    others = (
        ca.vertcat(*[v for _, v, _ in vars_ if v.numel()])
        if any(v.numel() for _, v, _ in vars_)
        else ca.SX(0, 1)
    )
    pieces, offset = [], np.zeros(plant.n)
    for i in range(plant.n):
        for k, h in _terms(rows[i]):
            name = plant.state_names[i]
            h0 = ca.substitute(h, others, ca.DM.zeros(others.numel())) if others.numel() else h
            for mat, v, vnames in vars_:
                for c in range(v.numel()):
                    b = ca.jacobian(h, v[c])
                    if not _const(b, others):
                        raise DerivationError(
                            f"{what} row {name!r}: the term {str(k * h)[:100]} is nonlinear in {vnames[c]!r}; inputs, "
                            "unknown inputs and faults must enter affinely (their coefficients may depend on the "
                            "states): rewrite the term, or declare premises yourself (b.premise)"
                        )
                    b = ca.substitute(b, others, ca.DM.zeros(others.numel())) if others.numel() else b
                    if not (b.is_constant() and float(ca.DM(b)) == 0.0):
                        pieces.append((mat, i, c, k, b, str(b) if ca.depends_on(b, x) else ""))
            if _const(h0, x):
                offset[i] += k * float(ca.DM(ca.evalf(h0)))
                continue
            z0 = float(ca.DM(ca.evalf(ca.substitute(h0, x, ca.DM.zeros(plant.n)))))
            if not np.isfinite(z0):
                raise DerivationError(
                    f"{what} row {name!r}: the term {str(k * h)[:100]} is not finite at x = 0, so it cannot be written "
                    "as bounded coefficients times the states; shift the states so that the plant is finite at 0, "
                    "or declare premises yourself (b.premise)"
                )
            offset[i] += k * z0
            for j in range(plant.n):
                if not ca.depends_on(h0, x[j]):
                    continue
                if not ca.depends_on(ca.jacobian(h0, x[j]), x):  # linear in x_j alone
                    pieces.append((xmat, i, j, k, ca.jacobian(h0, x[j]), ""))
                    continue
                c, text = _quotient(h0, x, j)
                if not ca.depends_on(c, x):  # a constant after all (e.g. 0 from x1 x2 along x1)
                    v = float(ca.DM(ca.evalf(c)))
                    if v != 0.0:
                        pieces.append((xmat, i, j, k, ca.SX(v), ""))
                    continue
                pieces.append((xmat, i, j, k, c, str(text)))
    return pieces, offset


def _group(plant: Plant, candidates: list[ca.SX], rng: np.random.Generator):
    """Indices of a representative per candidate, and the (alpha, beta) with ``c = alpha + beta rep``."""
    lo, hi = plant.region_lo, plant.region_hi
    x = plant.x
    N = 64
    pts = np.zeros((plant.n, N))
    for j in range(plant.n):
        if np.isnan(lo[j]):
            pts[j] = plant.x0[j] + rng.standard_normal(N)
        else:
            pts[j] = lo[j] + (hi[j] - lo[j]) * rng.random(N)
    F = ca.Function("cands", [x], [ca.vertcat(*candidates)]) if candidates else None
    vals = np.array(F.map(N)(pts)) if candidates else np.zeros((0, N))
    reps, rep_of, coef = [], [], []
    for k in range(len(candidates)):
        v = vals[k]
        found = None
        for r in reps:
            A = np.column_stack([np.ones(N), vals[r]])
            ab, *_ = np.linalg.lstsq(A, v, rcond=None)
            if np.max(np.abs(A @ ab - v)) <= 1e-9 * (1.0 + np.max(np.abs(v))):
                found = (r, float(ab[0]), float(ab[1]))
                break
        if found is None:
            reps.append(k)
            found = (k, 0.0, 1.0)
        rep_of.append(found[0])
        coef.append(found[1:])
    return reps, rep_of, coef


def premise_form(plant: Plant, seed: int = 0) -> tuple[Plant, list[str]]:
    """The plant rewritten with automatically found premises (see the module docstring), and notes.

    A plant without any nonlinear term gets no premise: one rule. Raises
    :class:`~fte_casadi.errors.DerivationError` naming the term that cannot be written so, or when
    more than :data:`MAX_PREMISES` premises would be needed."""
    pieces_f, off_f = _split(plant, "drift")
    pieces_g, off_g = _split(plant, "diffusion")
    if np.any(off_g):
        raise DerivationError(
            "the diffusion has a term that is not proportional to x, u, f or d2 (additive noise): the paper's model has none"
        )
    pieces = pieces_f + pieces_g
    cand = [p for p in pieces if p[5]]  # non-constant coefficients
    for p in cand:
        for j in range(plant.n):
            if ca.depends_on(p[4], plant.x[j]) and np.isnan(plant.region_lo[j]):
                raise DerivationError(
                    f"the coefficient {p[5][:80]} depends on state {plant.state_names[j]!r}, which has no bounds: "
                    f"give them with b.region({plant.state_names[j]}=(lower, upper))"
                )
    reps, rep_of, coef = _group(plant, [p[4] for p in cand], np.random.default_rng(seed))
    q = len(reps)
    texts = [cand[r][5] for r in reps]
    if q > MAX_PREMISES:
        raise DerivationError(
            f"the plant needs {q} premises ({2**q} rules), more than {MAX_PREMISES}: {'; '.join(texts)}. Declare some "
            "premises yourself (b.premise) so that terms share them, narrow the region so that some coefficients "
            "become nearly constant, or linearise at operating points instead (b.operating_points)"
        )
    if q > WARN_PREMISES:
        warnings.warn(
            f"the automatic sector method found {q} premises ({2**q} rules): {'; '.join(texts)}; the design will be "
            "slow and conservative: consider declaring premises yourself or linearising",
            RuntimeWarning,
            stacklevel=3,
        )
    z = ca.SX.sym("z", q)
    mats = {k: ca.SX.zeros(plant.n, dim) for k, dim in (
        ("A", plant.n), ("B", plant.m), ("Bd", plant.ld), ("Bf", plant.lf),
        ("W", plant.n), ("G", plant.m), ("Gf", plant.lf), ("M", plant.d2.numel()))}  # fmt: skip
    ci = 0
    for mat, i, j, k, e, text in pieces:
        if text:
            a, b = coef[ci]
            e = a + b * z[reps.index(rep_of[ci])]
            ci += 1
        mats[mat][i, j] += k * e
    x, u, d, f, d2 = plant.x, plant.u, plant.d, plant.f, plant.d2

    def mv(M, v):
        return ca.mtimes(M, v) if v.numel() else ca.SX.zeros(plant.n)

    drift = mv(mats["A"], x) + mv(mats["B"], u) + mv(mats["Bd"], d) + mv(mats["Bf"], f) + ca.DM(off_f)
    diff = mv(mats["W"], x) + mv(mats["G"], u) + mv(mats["Gf"], f) + mv(mats["M"], d2)
    z_exprs = ca.vertcat(*[cand[r][4] for r in reps]) if q else ca.SX(0, 1)
    names = tuple(f"z{k + 1}" for k in range(q))
    work = dataclasses.replace(plant, z=z if q else ca.SX(0, 1), z_names=names, z_exprs=z_exprs, z_texts=tuple(texts),
                               drift_z=drift, diffusion_z=diff)  # fmt: skip
    notes = [f"premises found automatically from the plain equations: {q}"] + [
        f"{nm} = {t}" for nm, t in zip(names, texts)
    ]
    if np.any(off_f):
        notes.append(f"constant drift offset a = {np.round(off_f, 6).tolist()} (kept in every rule)")
    return work, notes
