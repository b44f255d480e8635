"""The centring Newton method and phase 1: barrier methods in numpy on LMIs given as affine maps.

:func:`centre` turns a solver's answer into a point that depends on the data only. The conic
optimum of an LMI problem is in general neither unique nor well conditioned: solvers stop at
different points of a flat optimal face, and two machines' floating point lands on different
points. The centred point is the minimiser of the strictly convex function
``c^T v / mu + sum_k -log det(-F_k(v))`` (a point of the central path) with ``mu`` fixed by
``mu * nu = eta * (c^T v + floor)``, i.e. the point whose duality gap is the fraction ``eta`` of
its own objective (``nu`` = the barrier's degree, the sum of the LMI sizes). It is unique when
the map ``v -> (F_k(v))_k`` is injective, it depends smoothly on the data, and it does not depend
on the solver: the solver's point only serves as a strictly feasible start for damped Newton
steps, which converge to it quadratically. :func:`phase1` decides feasibility the same way, and
:func:`numpy_first` uses it in place of a conic solver where that is cheaper.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from ...errors import CentringError
from ._sdp import AffineLMI, ConicProblem, SolveResult

__all__ = [
    "Centred",
    "centre",
    "phase1",
    "phase1_active",
    "numpy_first",
    "ACTIVE_ADD",
    "PHASE1_FACTOR",
    "CENTRE_LOOSE",
    "CENTRE_NEAR",
]


@dataclass(frozen=True)
class Centred:
    v: np.ndarray
    mu: float
    newton_steps: int
    min_slack: float  # smallest eigenvalue of -F_k(v) over all LMIs


class _Barrier:
    """``-sum_k log det(-F_k(v))`` of LMIs given as ``(F0, F)``, with the unknowns it involves.

    LMIs of equal size and equal number of unknowns they depend on (their support) are stacked,
    so that one batched Cholesky factorisation, inverse and product serves them all (these
    problems have a handful of small LMIs, or many alike, one per rule; Python overhead per LMI
    would otherwise dominate a Newton step). Each LMI's derivatives are formed over its own
    support only and added into the gradient and Hessian there: rule i's (46) holds rule i's
    gain scale among r of them, and a dense Hessian over all of them grew like r^3. The unknowns
    of a symmetric matrix that an LMI holds in :class:`Kron` terms take the Kronecker route
    (:meth:`_kron_derivatives`); the rest of its support (a few scalars) the dense one.
    """

    def __init__(self, lmis: Sequence[AffineLMI], nv: int):
        self.nu = float(sum(L.k for L in lmis))
        self.nv = nv
        supports = [np.flatnonzero(np.any(L.F.reshape(nv, -1), axis=1)) for L in lmis]
        #: unknowns some LMI depends on (the others are left where they are)
        self.free = np.unique(np.concatenate(supports)) if supports else np.zeros(0, dtype=int)
        pos = np.full(nv, -1)
        pos[self.free] = np.arange(len(self.free))
        self.pos = pos
        dense = []
        for L, sp in zip(lmis, supports):
            kr = L.kron
            dense.append(sp if kr is None else sp[(sp < kr.start) | (sp >= kr.start + kr.size)])
        self.groups = []
        self._last = None  # (factors, derivatives) of the last point asked
        self.hess = []  # per group, how its Hessian terms are gathered and added (fixed by the supports)
        self.krons = []  # per group, (start, n, A, B) of its Kron terms, or None
        self._gather: dict = {}  # per Kron unknown, where its Hessian entries are gathered (_kron_finish)
        self._cross: dict = {}  # per group's Kron terms, where its cross terms are gathered (_kron_derivatives)

        def sig(L):
            return None if L.kron is None else (L.kron.start, L.kron.n, L.kron.A.shape[0])

        keys = {(L.k, len(sp), len(dn), sig(L)) for L, sp, dn in zip(lmis, supports, dense)}
        for key in sorted(keys, key=repr):
            members = [(L, sp, dn) for L, sp, dn in zip(lmis, supports, dense)
                       if (L.k, len(sp), len(dn), sig(L)) == key]  # fmt: skip
            F0 = np.stack([L.F0 for L, _, _ in members])  # (g, k, k)
            idx = np.stack([sp for _, sp, _ in members])  # (g, ns): the unknowns of each
            Fs = np.stack([L.F[sp] for L, sp, _ in members])  # (g, ns, k, k)
            idd = np.stack([dn for _, _, dn in members]).reshape(len(members), -1)  # (g, nd)
            Fd = np.stack([L.F[dn] for L, _, dn in members]).reshape(
                len(members), idd.shape[1], *F0.shape[1:]
            )
            self.groups.append((key[0], F0, idx, Fs, pos[idd], Fd))
            self.hess.append(self._hessian_layout(key[0], pos[idd], len(self.free)))
            if key[3] is None:
                self.krons.append(None)
            else:
                start, n, _ = key[3]
                A = np.stack([L.kron.A for L, _, _ in members])  # (g, H, n, k)
                B = np.stack([L.kron.B for L, _, _ in members])
                self.krons.append((start, n, A, B))

    @staticmethod
    def _hessian_layout(k: int, ip: np.ndarray, nf: int):
        """``(tri, shared, where)``: the upper-triangle gather of a large LMI (k >= 24: ``tr(W_l W_m)`` over
        the upper triangles, off-diagonal entries weighted sqrt(2), half the products; for small LMIs the
        gather costs more than it saves: None), whether every LMI of the group has the same support, and
        else the flat positions in the Hessian where each LMI's block is added."""
        tri = None
        if k >= 24:
            iu, ju = np.triu_indices(k)
            tri = (iu, ju, np.where(iu == ju, 1.0, np.sqrt(2.0)))
        shared = ip.shape[0] > 1 and bool(np.all(ip == ip[0]))
        where = None if shared else (ip[:, :, None] * nf + ip[:, None, :]).ravel()
        return tri, shared, where

    def factors(self, v):
        out = []
        for _, F0, idx, Fs, _, _ in self.groups:
            M = -(F0 + (v[idx][:, None, :] @ Fs.reshape(*idx.shape, -1)).reshape(F0.shape))
            try:
                out.append(np.linalg.cholesky(M))
            except np.linalg.LinAlgError:
                return None
        return out

    @staticmethod
    def value(fac) -> float:
        return -2.0 * sum(float(np.sum(np.log(np.diagonal(Lc, axis1=-2, axis2=-1)))) for Lc in fac)

    def derivatives(self, fac):
        if self._last is not None and self._last[0] is fac:  # the start point: _fit_mu, then Newton
            return self._last[1]
        out = self._derivatives(fac)
        self._last = (fac, out)
        return out

    def _derivatives(self, fac):
        nf = len(self.free)
        g = np.zeros(nf)
        Hm = np.zeros((nf, nf))
        acc: dict = {}  # per Kron unknown: (n, sum of A_h B_h^T, sum of the Kronecker products)
        for Lc, (_, _, _, _, ip, Fs), (tri, shared, where), kr in zip(
            fac, self.groups, self.hess, self.krons
        ):
            Li = np.linalg.inv(Lc)  # (g, k, k)
            LiT = np.swapaxes(Li, -1, -2)
            W = Li[:, None] @ Fs @ LiT[:, None]  # W_l = L^-1 F_l L^-T, (g, nd, k, k)
            if ip.shape[1]:
                g += np.bincount(
                    ip.ravel(), weights=np.trace(W, axis1=-2, axis2=-1).ravel(), minlength=nf
                )  # tr(W_l)
                if tri is not None:
                    Wt = W[..., tri[0], tri[1]] * tri[2]  # (g, nd, k(k+1)/2)
                else:
                    Wt = W.reshape(*W.shape[:2], -1)
                if shared:  # one support for all (e.g. Pt in (55) and (64))
                    W2 = np.swapaxes(Wt, 0, 1).reshape(ip.shape[1], -1)
                    Hm[np.ix_(ip[0], ip[0])] += W2 @ W2.T
                else:
                    Hl = Wt @ np.swapaxes(Wt, -1, -2)  # Hess_lm = tr(W_l W_m) per LMI, over its support
                    Hm += np.bincount(where, weights=Hl.ravel(), minlength=nf * nf).reshape(nf, nf)
            if kr is not None:
                self._kron_derivatives(kr, LiT, W, ip, Hm, acc)
        self._kron_finish(g, Hm, acc)
        return g, Hm

    def _kron_derivatives(self, kr, LiT, W, ip, Hm, acc):
        """The terms of a group's Kron unknown P: with ``W(E) = L^-1 F_P(E) L^-T = sum_h A_h^T E B_h``
        (``A_h, B_h`` the Kron terms times ``L^-T``), the gradient ``tr W(E_ab) = (sum_h A_h B_h^T)_ab``,
        the Hessian ``tr(W(E_ab) W(E_cd)) = sum_hh' (B_h A_h'^T)_bc (B_h' A_h^T)_da`` (one product of
        n^2 x n^2 matrices over all pairs h, h' of all members, :meth:`_kron_finish`), and the cross terms
        with the dense unknowns ``tr(W(E_ab) W_l) = (sum_h A_h W_l B_h^T)_ab``."""
        start, n, A0, B0 = kr
        g, H, k = A0.shape[0], A0.shape[1], A0.shape[-1]
        A = A0 @ LiT[:, None]  # (g, H, n, k)
        B = B0 @ LiT[:, None]
        Am = A.reshape(g, H * n, k)
        Bm = B.reshape(g, H * n, k)
        Gm = np.moveaxis(A, 2, 0).reshape(n, -1) @ np.moveaxis(B, 2, 0).reshape(n, -1).T
        M = (Bm @ np.swapaxes(Am, 1, 2)).reshape(g, H, n, H, n)  # [g, h, b, h', c] = (B_h A_h'^T)_bc
        X1 = M.transpose(0, 1, 3, 2, 4).reshape(-1, n * n)  # rows (g, h, h')
        X2 = M.transpose(0, 3, 1, 2, 4).reshape(-1, n * n)  # rows (g, h, h'): B_h' A_h^T
        Hk = X1.T @ X2
        if start in acc:
            _, G0, H0 = acc[start]
            acc[start] = (n, G0 + Gm, H0 + Hk)
        else:
            acc[start] = (n, Gm, Hk)
        if ip.shape[1]:  # cross terms with the dense unknowns of each member
            AW = Am[:, None] @ W  # (g, nd, H n, k): A_h W_l
            AW = AW.reshape(g, -1, H, n, k).transpose(0, 1, 3, 2, 4).reshape(g, -1, n, H * k)
            C = AW @ np.swapaxes(B, 2, 3).reshape(g, 1, H * k, n)  # sum_h A_h W_l B_h^T, (g, nd, n, n)
            nf = Hm.shape[0]
            key = id(kr)  # the group's Kron terms: where its cross terms go is fixed for the barrier's life
            if key not in self._cross:
                iu, ju = np.triu_indices(n)
                rows = self.pos[start : start + len(iu)]
                self._cross[key] = (
                    iu,
                    ju,
                    np.where(iu == ju, 0.5, 1.0),
                    (ip[:, :, None] * nf + rows[None, None, :]).ravel(),
                )
            iu, ju, w, at = self._cross[key]
            X = ((C[:, :, iu, ju] + C[:, :, ju, iu]) * w).ravel()  # (g, nd, n(n+1)/2)
            Hx = np.bincount(at, weights=X, minlength=nf * nf).reshape(nf, nf)
            Hm += Hx + Hx.T

    def _kron_finish(self, g, Hm, acc):
        """Add the accumulated Kron terms of each unknown P into ``g`` and ``Hm`` in P's triangle coordinates:
        the unknown (a, b) is ``E_ab + E_ba`` (a < b) or ``E_aa``, so each entry sums four entries of the
        n^2 x n^2 product, gathered at positions fixed once per unknown."""
        for start, (n, Gm, Hk) in acc.items():
            if start not in self._gather:
                iu, ju = np.triu_indices(n)
                w = np.where(iu == ju, 0.5, 1.0)
                a, b, c, d = iu[:, None], ju[:, None], iu[None, :], ju[None, :]
                nn = n * n
                at = [
                    (y * n + z) * nn + t * n + x
                    for x, y, z, t in ((a, b, c, d), (b, a, c, d), (a, b, d, c), (b, a, d, c))
                ]
                self._gather[start] = (iu, ju, w, at, w[:, None] * w[None, :])
            iu, ju, w, at, ww = self._gather[start]
            rows = self.pos[start : start + len(iu)]
            g[rows] += w * (Gm[iu, ju] + Gm[ju, iu])
            flat = Hk.ravel()
            Hm[np.ix_(rows, rows)] += (flat[at[0]] + flat[at[1]] + flat[at[2]] + flat[at[3]]) * ww

    def slack(self, v) -> float:
        return min(
            float(np.linalg.eigvalsh(-(F0 + np.einsum("gs,gskl->gkl", v[idx], Fs))).min())
            for _, F0, idx, Fs, _, _ in self.groups
        )


def _newton(bar: _Barrier, c: np.ndarray, v: np.ndarray, fac, mu: float, tol: float, budget: list, stop=None):
    """Minimise ``c^T v / mu + barrier(v)`` from the strictly feasible ``v`` by Newton steps.

    Far from the minimiser (Newton decrement ``lambda >= 1/4``) the steps are damped by a
    backtracking line search; inside, the full step is taken: for a self-concordant function it
    stays feasible and converges quadratically, and no line search has to compare values of psi
    that differ below their round-off. The iteration ends when ``lambda^2 <= tol^2`` or when
    ``lambda^2`` stops falling (the round-off floor). ``budget = [steps, max_steps]`` counts the
    steps across calls; ``stop(v)`` (optional) ends it at the first iterate where it is true.
    """
    idx = bar.free
    prev, stalled = np.inf, 0
    while True:
        gb, Hm = bar.derivatives(fac)
        g = c[idx] / mu + gb
        dscale = 1.0 / np.sqrt(np.maximum(np.diag(Hm), 1e-300))
        try:
            d = -dscale * np.linalg.solve(Hm * dscale[:, None] * dscale[None, :], g * dscale)
        except np.linalg.LinAlgError:
            raise CentringError(
                "the Hessian of the barrier is singular: the LMIs do not fix every unknown"
            ) from None
        lam2 = float(-g @ d)
        if not np.isfinite(lam2):
            raise CentringError("non-finite Newton step")
        stalled = stalled + 1 if lam2 > 0.25 * prev else 0
        if lam2 <= tol**2 or (lam2 < 1e-10 and stalled >= 2):
            return v, fac  # converged, or at the round-off floor (the decrement no longer falls)
        prev = lam2
        budget[0] += 1
        if budget[0] > budget[1]:
            raise CentringError(f"Newton did not converge in {budget[1]} steps (decrement^2 {lam2:.2g})")
        dv = np.zeros_like(v)
        dv[idx] = d
        if lam2 < 0.0625:  # quadratic region: the full step
            vn = v + dv
            fn = bar.factors(vn)
            if fn is None:
                raise CentringError(f"a full Newton step left the feasible set (decrement^2 {lam2:.2g})")
        else:
            p0 = float(c @ v) / mu + bar.value(fac)
            t = 1.0
            while True:
                vn = v + t * dv
                fn = bar.factors(vn)
                if fn is not None and float(c @ vn) / mu + bar.value(fn) <= p0 - 0.25 * t * lam2:
                    break
                t *= 0.5
                if t < 1e-14:
                    raise CentringError(f"line search failed (decrement^2 {lam2:.2g})")
        v, fac = vn, fn
        if stop is not None and stop(v):
            return v, fac


def _decrement(bar: _Barrier, c: np.ndarray, fac) -> tuple[float, float, float] | None:
    """``(a, b, d)`` of the Newton decrement ``lambda^2(x) = a x^2 + 2 b x + d`` of ``x c^T v + barrier(v)``
    at the point, as a function of ``x = 1/mu`` (``a = c^T H^-1 c``, ``b = c^T H^-1 g``, ``d = g^T H^-1 g``);
    None when the Hessian is singular or ``c`` vanishes on the free unknowns."""
    gb, Hm = bar.derivatives(fac)
    cf = c[bar.free]
    dscale = 1.0 / np.sqrt(np.maximum(np.diag(Hm), 1e-300))
    try:
        sol = dscale[:, None] * np.linalg.solve(
            Hm * dscale[:, None] * dscale[None, :], np.c_[cf, gb] * dscale[:, None]
        )
    except np.linalg.LinAlgError:
        return None
    a, b, d = float(cf @ sol[:, 0]), float(cf @ sol[:, 1]), float(gb @ sol[:, 1])
    if not (a > 0 and np.isfinite(a) and np.isfinite(b) and np.isfinite(d)):
        return None
    return a, b, d


def _fit_mu(bar: _Barrier, c: np.ndarray, fac) -> float:
    """The ``mu`` for which the point is closest to central: the minimiser over ``x = 1/mu`` of the Newton
    decrement ``lambda^2(x)`` (:func:`_decrement`). When the objective does not pull the point (``b >= 0``),
    the ``mu`` at which it adds ``1/4`` to ``lambda^2``. A path followed from there needs a few Newton steps
    per stage; started from ``mu`` set by the final gap instead, the first stage crossed the whole path in
    hundreds of damped steps. Only the path changes, not the point it ends at (0 when ``c`` vanishes on the
    free unknowns)."""
    q = _decrement(bar, c, fac)
    if q is None:
        return 0.0
    a, b, _ = q
    return a / -b if b < 0 else 2.0 * np.sqrt(a)


#: the Newton decrement to which the centring's stages far from the fixed point are centred (the quadratic
#: region's edge); only stages within CENTRE_NEAR of the fixed point are centred to the full tolerance, so the
#: point returned is the same (64-rule chain: 319 -> 273 Newton steps in its two centrings)
CENTRE_LOOSE = 0.25
CENTRE_NEAR = 0.1


def centre(
    lmis: Sequence[AffineLMI],
    c: np.ndarray,
    v0: np.ndarray,
    *,
    eta: float = 0.01,
    floor: float = 0.0,
    tol: float = 1e-9,
    max_steps: int = 400,
) -> Centred:
    """The central-path point of ``min c^T v s.t. F_k(v) <= 0`` whose gap is ``eta (c^T v + floor)``.

    Damped Newton steps on ``psi(v) = c^T v / mu - sum_k log det(-F_k(v))`` from the strictly
    feasible ``v0`` (any point of a feasibility solve: the path is followed from there), with
    ``mu`` lowered at most eightfold per stage until ``mu = eta (c^T v + floor) / nu`` holds
    (a fixed point, reached linearly with ratio about ``eta``). Unknowns that no LMI involves
    keep their value from ``v0``. Raises :class:`CentringError` when ``v0`` is not strictly
    feasible, when the Hessian is singular or when Newton does not converge.
    """
    v = np.asarray(v0, dtype=float).copy()
    bar = _Barrier(lmis, len(v))
    fac = bar.factors(v)
    if fac is None:
        raise CentringError("the starting point is not strictly feasible")
    mu = eta * (float(c @ v) + floor) / bar.nu
    if not mu > 0:
        raise CentringError(
            f"the objective plus floor must be positive at the start (got {float(c @ v) + floor:g})"
        )
    mu = max(mu, _fit_mu(bar, c, fac))
    budget = [0, max_steps]
    prev = None  # (mu, h(mu)) of the stage before, for the secant step
    loose = True  # far from the fixed point the path is only followed: centred to CENTRE_LOOSE, not to tol
    for _stage in range(200):
        v, fac = _newton(bar, c, v, fac, mu, CENTRE_LOOSE if loose else tol, budget)
        target = eta * (float(c @ v) + floor) / bar.nu
        h = target - mu  # the fixed point is h(mu) = 0
        if not loose and abs(h) <= 1e-13 * abs(mu):
            break
        loose = abs(h) > CENTRE_NEAR * abs(mu)
        nxt = target
        if prev is not None and h != prev[1]:
            sec = mu - h * (mu - prev[0]) / (h - prev[1])  # secant on h: superlinear near the fixed point
            if sec > 0:
                # not below half the target: the objective flattens near the optimum, so the secant
                # overshoots there, and a point closer to the optimal face than the fixed point takes
                # hundreds of damped steps to leave again
                nxt = max(sec, 0.5 * target)
        prev = (mu, h)
        # follow the central path at most eightfold per stage (a far start converges in a few damped
        # steps per stage), and never further than halfway to zero
        mu = min(max(nxt, mu / 8.0), 8.0 * mu)
    else:  # the point would not be the unique centred one: say so instead of returning it
        raise CentringError(
            f"the centring did not reach its fixed point in 200 stages (mu {mu:.3g}, {budget[0]} steps)"
        )
    return Centred(v, mu, budget[0], bar.slack(v))


#: phase 1 lowers mu by this factor per stage: measured with the Kronecker Hessian, a factor of 8 took up to 300
#: damped Newton steps in one stage near the boundary (64 rules: 914 steps in six decisions), 4 takes 488 there
#: and costs a 24-state chain 10 % more steps than 8
PHASE1_FACTOR = 4.0


def phase1(
    soft: Sequence[AffineLMI], hard: Sequence[AffineLMI], v0: np.ndarray, *, max_steps: int = 400
) -> np.ndarray | None:
    """Decide whether ``F_k(v) < 0`` for all ``soft`` and ``hard`` LMIs has a solution, deterministically.

    The barrier method on ``min t s.t. F_k(v) <= t I`` (soft) and ``F_k(v) < 0`` (hard, which
    ``v0`` must satisfy strictly), from ``v0``: after each centring, ``t < 0`` gives a strictly
    feasible point (returned), ``t - nu mu > 0`` proves that none exists (the duality bound;
    returns None). Unlike a conic solver's status, the answer does not depend on the solver.
    """
    nv = len(v0)
    soft_t = [AffineLMI(L.name, L.F0, np.concatenate([L.F, -np.eye(L.k)[None]], axis=0), kron=L.kron)
              for L in soft]  # fmt: skip
    hard_t = [AffineLMI(L.name, L.F0, np.concatenate([L.F, np.zeros((1, L.k, L.k))], axis=0), kron=L.kron)
              for L in hard]  # fmt: skip
    t0 = max(float(np.linalg.eigvalsh(L.value(v0))[-1]) for L in soft)
    if t0 < 0:
        return np.asarray(v0, dtype=float).copy()
    scale = max(1.0, max(float(np.abs(L.value(v0)).max()) for L in soft))
    v = np.concatenate([np.asarray(v0, dtype=float), [t0 + 1e-3 * scale]])
    bar = _Barrier(soft_t + hard_t, nv + 1)
    fac = bar.factors(v)
    if fac is None:
        raise CentringError("phase 1: the starting point does not satisfy the fixed LMIs strictly")
    c = np.zeros(nv + 1)
    c[-1] = 1.0
    mu = min((v[-1] + 1e-2 * scale) / bar.nu, max(_fit_mu(bar, c, fac), 1e-300))
    budget = [0, max_steps]
    for _stage in range(60):
        v, fac = _newton(bar, c, v, fac, mu, 5e-2, budget, stop=lambda w: w[-1] < 0)
        if v[-1] < 0:
            return v[:nv]
        # t* >= t(v_mu) - nu mu at a central point; Newton stops at decrement <= 0.05, where the
        # bound holds within a few per cent: 1.5 nu mu is a safe margin
        if v[-1] - 1.5 * bar.nu * mu > 0:
            return None
        mu /= PHASE1_FACTOR
    return None


def _strictly(L: AffineLMI, v: np.ndarray) -> bool:
    try:
        np.linalg.cholesky(-L.value(v))
    except np.linalg.LinAlgError:
        return False
    return True


#: how many of the soft LMIs most violated at the start :func:`phase1_active` adds to the ones it was given
ACTIVE_ADD = 8


def phase1_active(
    soft: Sequence[AffineLMI], hard: Sequence[AffineLMI], v0: np.ndarray, active=(), *, tied=None,
    max_steps: int = 400,
) -> tuple[np.ndarray | None, list[int]]:  # fmt: skip
    """:func:`phase1` on a growing subset of the ``soft`` LMIs (one per rule, of which a few bind).

    The subset starts as ``active`` plus the ACTIVE_ADD soft LMIs most violated at ``v0``; a point found
    for it is checked against every soft LMI (a Cholesky factorisation each), and the ones it violates
    join the subset, from that point. The answer is the same fact as :func:`phase1`'s on all of them: a
    point is returned only when it satisfies every LMI strictly, and a subset without a point proves that
    the whole set has none. ``tied[i]`` are hard LMIs that only concern soft LMI i's own unknowns (a
    rule's gain cap), posed only while i is in the subset (alone, the barrier of a cap would push an
    unknown that no other LMI holds away without bound). Returns the point (or None) and the subset
    used, which the next question about the same LMIs starts from.

    Measured on the 64-rule chain (step 5's six decisions in alpha): 8 to 16 of the 64 rules decide
    each of them, and the six decisions cost 490 Newton steps on all 64 LMIs before, 280 on 16 or fewer."""
    tied = tied if tied is not None else [[] for _ in soft]
    worst = np.argsort([-float(np.linalg.eigvalsh(L.value(v0))[-1]) for L in soft], kind="stable")
    act = list(dict.fromkeys([int(i) for i in active] + [int(i) for i in worst[:ACTIVE_ADD]]))
    v = np.asarray(v0, dtype=float)
    while True:
        fixed = list(hard) + [h for i in act for h in tied[i]]
        w = phase1([soft[i] for i in act], fixed, v, max_steps=max_steps)
        if w is None:
            return None, act
        bad = [i for i in range(len(soft)) if i not in set(act) and not _strictly(soft[i], w)]
        if not bad:  # the next question starts from the rules closest to binding here
            top = [-float(np.linalg.eigvalsh(L.value(w))[-1]) for L in soft]
            return w, [int(i) for i in np.argsort(top, kind="stable")[:ACTIVE_ADD]]
        act += bad
        v = w


def numpy_first(prob: ConicProblem, soft: int, v0: np.ndarray, hard=()) -> SolveResult | None:
    """A heavy problem's start point by :func:`phase1` in numpy instead of a conic solver: its first
    ``soft`` LMIs are the soft ones, the rest (with ``hard``) must hold strictly at ``v0``; the parameter
    ``p`` is 0. Phase 1 either finds a strictly feasible point or proves that none exists (the duality
    bound); with the Kronecker Hessian its Newton steps cost less than a conic solver's iterations on a
    dense PSD cone (24-state chain: an infeasible (45) 30 s with SCS, a feasible (46) 1.2-18 s). None when
    it fails (the conic solvers then). (Not :func:`phase1_active`: its barely feasible point cost the
    centring that follows more steps than it saved, measured on the 64-rule chain.)"""
    t0 = time.perf_counter()
    try:
        v = phase1(prob.lmis[:soft], list(prob.lmis[soft:]) + list(hard), v0)
    except CentringError:
        return None
    elapsed = time.perf_counter() - t0
    prob.seconds += elapsed
    rows = sum(L.k * (L.k + 1) // 2 for L in prob.lmis)
    prob.notes.append(f"phase 1 in numpy gave this answer ({'a point' if v is not None else 'infeasible'}, "
                      f"{elapsed:.2g} s): {len(prob.lmis)} LMIs, {rows} rows of PSD cones for a conic solver")  # fmt: skip
    return SolveResult("optimal" if v is not None else "infeasible", v, elapsed, solver="phase 1 (numpy)")
