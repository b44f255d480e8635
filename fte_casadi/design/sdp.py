"""LMIs as affine maps of one variable vector, their cvxpy form, and the centring Newton method.

Every LMI of the design is written once, as a numpy function of plain matrices (the builders of
:mod:`fte_casadi.design.certify`, which also compute the certificates). For a solve, the
unknowns are packed into one vector ``v`` (:class:`Layout`) and the builder is evaluated at
``v = 0`` and at the unit vectors, which gives the LMI exactly as ``F(v) = F0 + sum_l v_l F_l``
(the builders are affine in the unknowns; :func:`affine_lmi` checks it at a random point).
cvxpy then receives one precomputed affine expression per LMI, which it compiles in a few
milliseconds; a scalar parameter ``p`` (the observer decay rate) may enter as ``p * G(v)``, which
keeps the problem DPP so that re-solving for another ``p`` does not re-canonicalise it.

:func:`centre` turns the solver's answer into a point that depends on the data only. The conic
optimum of an LMI problem is in general neither unique nor well conditioned: solvers stop at
different points of a flat optimal face, and two machines' floating point lands on different
points (issue #9). The centred point is the minimiser of the strictly convex function
``c^T v / mu + sum_k -log det(-F_k(v))`` (a point of the central path) with ``mu`` fixed by
``mu * nu = eta * (c^T v + floor)``, i.e. the point whose duality gap is the fraction ``eta`` of
its own objective (``nu`` = the barrier's degree, the sum of the LMI sizes). It is unique when
the map ``v -> (F_k(v))_k`` is injective, it depends smoothly on the data, and it does not depend
on the solver: the solver's point only serves as a strictly feasible start for damped Newton
steps, which converge to it quadratically.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import cvxpy as cp
import numpy as np

from ..errors import CentringError as CentringError
from .linalg import sym as _sym

__all__ = [
    "Var",
    "Layout",
    "AffineLMI",
    "affine_lmi",
    "MarginLMI",
    "Kron",
    "margin_lmi",
    "ConicProblem",
    "SolveResult",
    "SOLVED",
    "LARGE_CONE",
    "Centred",
    "CentringError",
    "centre",
    "phase1",
    "SOLVER_SETTINGS",
]

#: settings passed explicitly to every solve. The solves are feasibility problems whose point only
#: has to lie strictly inside LMIs with half the margins they were posed with (checked with numpy
#: afterwards), so the first-order SCS is asked for 1e-6, not for an interior-point accuracy.
#: Clarabel factors its KKT system with faer's supernodal LDL: a PSD cone of size k is a dense block
#: of k(k+1)/2 rows there, which the default QDLDL factors as if sparse (measured on the chain
#: family, one step-3 solve: n = 12 4.95 s -> 0.85 s, n = 16 57 s -> 3.3 s); one thread, so that
#: a run repeats itself exactly.
SOLVER_SETTINGS = {
    "CLARABEL": {
        "max_iter": 200,
        "tol_feas": 1e-9,
        "tol_gap_abs": 1e-9,
        "tol_gap_rel": 1e-9,
        "direct_solve_method": "faer",
        "max_threads": 1,
    },
    "SCS": {"max_iters": 100_000, "eps_abs": 1e-6, "eps_rel": 1e-6},
}


@dataclass(frozen=True)
class Var:
    """One unknown: a matrix (``symmetric`` or general), a vector or a scalar (``shape == ()``)."""

    name: str
    shape: tuple[int, ...]
    symmetric: bool = False

    @property
    def size(self) -> int:
        if self.symmetric:
            n = self.shape[0]
            return n * (n + 1) // 2
        return int(np.prod(self.shape, dtype=int))


class Layout:
    """The unknowns of one problem packed into one vector (upper triangles of symmetric ones)."""

    def __init__(self, *variables: Var):
        self.vars = tuple(variables)
        self.offsets = np.cumsum([0] + [v.size for v in self.vars])
        self.size = int(self.offsets[-1])
        self._triu = {v.name: np.triu_indices(v.shape[0]) for v in self.vars if v.symmetric}

    def unpack(self, v: np.ndarray) -> dict:
        out = {}
        for var, a in zip(self.vars, self.offsets[:-1]):
            chunk = np.asarray(v[a : a + var.size], dtype=float)
            if var.symmetric:
                n = var.shape[0]
                M = np.zeros((n, n))
                M[self._triu[var.name]] = chunk
                out[var.name] = M + np.triu(M, 1).T
            elif var.shape == ():
                out[var.name] = float(chunk[0])
            else:
                out[var.name] = chunk.reshape(var.shape)
        return out

    def pack(self, **values) -> np.ndarray:
        """The vector holding ``values`` (the inverse of :meth:`unpack`; missing names are zero)."""
        v = np.zeros(self.size)
        for var, a in zip(self.vars, self.offsets[:-1]):
            if var.name not in values:
                continue
            x = np.asarray(values[var.name], dtype=float)
            v[a : a + var.size] = x[self._triu[var.name]] if var.symmetric else x.ravel()
        return v

    def index(self, name: str) -> slice:
        k = [v.name for v in self.vars].index(name)
        return slice(int(self.offsets[k]), int(self.offsets[k + 1]))

    def support(self, *parts) -> np.ndarray:
        """Indices of ``v`` for ``parts``: a variable's name (all of it) or ``(name, i)`` (its entry i)."""
        out = []
        for part in parts:
            if isinstance(part, str):
                sl = self.index(part)
                out.extend(range(sl.start, sl.stop))
            else:
                name, i = part
                out.append(self.index(name).start + int(i))
        return np.asarray(sorted(set(out)), dtype=int)


@dataclass(frozen=True)
class Kron:
    """How one symmetric unknown ``P`` (n x n, its triangle at ``v[start:]``) enters an LMI of size k:
    ``sum_h A_h^T P B_h`` (``A_h, B_h`` of shape (n, k); the sum is symmetric for symmetric P).

    The LMIs of the design hold their matrix unknown in a few such terms (``Pbar T A_i``,
    ``Phi^T T^T Pbar T Phi``, ``J1^T T^T Pbar (I - Cbar^+ Cbar)``, ...). Knowing them, the barrier's
    Hessian over P's n(n+1)/2 unknowns is a sum of Kronecker products of n x n matrices (O(H^2 n^4)
    per LMI) instead of traces of products of k x k matrices (O(n^4 k^2)), and the LMI's coefficients
    of P are formed from the terms instead of one evaluation of the builder per unknown. Terms with
    proportional ``A_h`` are merged (``c A^T P B' = A^T P (c B')``), so that e.g. the decay term
    ``2 alpha Pbar`` joins ``Pbar T Abar_i`` instead of adding to the H^2 pairs.
    """

    start: int
    A: np.ndarray  # (H, n, k)
    B: np.ndarray  # (H, n, k)

    @staticmethod
    def of(start: int, terms, n: int, k: int) -> Kron:
        """From ``terms``: pairs ``(U, V)`` meaning ``U^T P V + V^T P U``, or ``(U, None)`` meaning ``U^T P U``."""
        halves = []
        for U, V in terms:
            U = np.asarray(U, dtype=float).reshape(n, k)
            halves += [(U, U)] if V is None else [(U, np.asarray(V, dtype=float).reshape(n, k)), (V, U)]
        return Kron._merged(start, halves, n, k)

    @staticmethod
    def _merged(start: int, halves, n: int, k: int) -> Kron:
        A: list = []
        B: list = []
        for a, b in halves:
            a = np.asarray(a, dtype=float)
            for h, ah in enumerate(A):  # a = c A_h: c A_h^T P b joins A_h^T P B_h
                c = float(np.vdot(ah, a)) / max(float(np.vdot(ah, ah)), 1e-300)
                if np.linalg.norm(a - c * ah) <= 1e-13 * np.linalg.norm(a):
                    B[h] = B[h] + c * b
                    break
            else:
                A.append(a)
                B.append(np.asarray(b, dtype=float))
        shape = (len(A), n, k)
        return Kron(start, np.reshape(A, shape), np.reshape(B, shape))

    @property
    def n(self) -> int:
        return self.A.shape[1]

    @property
    def size(self) -> int:
        return self.n * (self.n + 1) // 2

    def scaled(self, c: float) -> Kron:
        return Kron(self.start, self.A, c * self.B)

    def plus(self, other: Kron | None) -> Kron:
        if other is None:
            return self
        if other.start != self.start or other.A.shape[1:] != self.A.shape[1:]:
            raise RuntimeError("internal error: Kron terms of different unknowns added")
        n, k = self.A.shape[1:]
        return Kron._merged(self.start, list(zip(self.A, self.B)) + list(zip(other.A, other.B)), n, k)

    def basis(self) -> np.ndarray:
        """The LMI's coefficients of P's unknowns (upper triangle, row by row), (n(n+1)/2, k, k)."""
        n, k = self.A.shape[1:]
        # A_h^T E_ab B_h = outer(A_h[a], B_h[b]): Q[a, b] (H summed), then E_ab + E_ba, or E_aa alone
        Q = np.einsum("hap,hbq->abpq", self.A, self.B, optimize=True)
        iu, ju = np.triu_indices(n)
        off = (iu != ju)[:, None, None]
        return Q[iu, ju] + np.where(off, Q[ju, iu], 0.0)


def _kron(layout: Layout, kron, k: int) -> Kron | None:
    """``(name, terms)`` (:meth:`Kron.of`) as a :class:`Kron` of ``layout``."""
    if kron is None:
        return None
    name, terms = kron
    sl = layout.index(name)
    n = layout.vars[[v.name for v in layout.vars].index(name)].shape[0]
    return Kron.of(sl.start, terms, n, k)


@dataclass(frozen=True)
class AffineLMI:
    """``F(v, p) = F0 + sum_l v_l (F_l + p G_l)  <=  0`` (negative semidefinite), named for messages.

    ``kron`` (and ``kron_G`` for the parameter's term), when given, say how a symmetric matrix
    unknown enters (:class:`Kron`); ``F`` holds its coefficients all the same."""

    name: str
    F0: np.ndarray
    F: np.ndarray  # (nv, k, k)
    G: np.ndarray | None = None  # (nv, k, k), the coefficient of the parameter p
    kron: Kron | None = None
    kron_G: Kron | None = None

    @property
    def k(self) -> int:
        return self.F0.shape[0]

    def at(self, p: float) -> AffineLMI:
        """The LMI with the parameter fixed at ``p``."""
        if self.G is None or p == 0.0:
            return AffineLMI(self.name, self.F0, self.F, kron=self.kron)
        kron = self.kron
        if self.kron_G is not None:
            kron = self.kron_G.scaled(p) if kron is None else kron.plus(self.kron_G.scaled(p))
        return AffineLMI(self.name, self.F0, self.F + p * self.G, kron=kron)

    def value(self, v: np.ndarray, p: float = 0.0) -> np.ndarray:
        M = self.F0 + np.tensordot(v, self.F, 1)
        if self.G is not None and p:
            M = M + p * np.tensordot(v, self.G, 1)
        return M


def _basis(layout: Layout, builder: Callable[..., np.ndarray], support: np.ndarray | None = None, kron=None):
    """``(F0, F, kron)``: the builder at zero and its coefficients, one evaluation per unknown of ``support``
    (all by default), except those of ``kron``'s unknown, which come from its terms."""
    zero = builder(**layout.unpack(np.zeros(layout.size)))
    F0 = _sym(np.asarray(zero, dtype=float))
    F = np.zeros((layout.size, *F0.shape))
    kr = _kron(layout, kron, F0.shape[0])
    skip = range(0) if kr is None else range(kr.start, kr.start + kr.size)
    e = np.zeros(layout.size)
    for l in range(layout.size) if support is None else support:
        if l in skip:
            continue
        e[l] = 1.0
        F[l] = _sym(np.asarray(builder(**layout.unpack(e)), dtype=float)) - F0
        e[l] = 0.0
    if kr is not None:
        F[skip.start : skip.stop] = kr.basis()
    return F0, F, kr


def affine_lmi(
    name: str,
    layout: Layout,
    builder: Callable[..., np.ndarray],
    param: Callable[..., np.ndarray] | None = None,
    support: np.ndarray | None = None,
    kron=None,
    kron_param=None,
) -> AffineLMI:
    """The affine map of ``builder(**unknowns)`` (and of the parameter's coefficient ``param``).

    The builder must be affine in the unknowns; this is checked at a random point, so a builder
    that is not (a bug) fails loudly instead of giving a wrong LMI. ``support`` (indices of ``v``)
    names the only unknowns the builder depends on (e.g. rule i's own gain scale among r of them):
    the others are not evaluated, and the random check (every unknown nonzero) fails loudly when
    the builder depends on one outside it. ``kron = (name, terms)`` says how the symmetric unknown
    ``name`` enters (:class:`Kron`; ``kron_param`` the same for ``param``): its coefficients come
    from the terms, and the same random check fails loudly when the terms are not the builder's.
    """
    F0, F, kr = _basis(layout, builder, support, kron)
    v = np.random.default_rng(12345).standard_normal(layout.size)
    direct = _sym(np.asarray(builder(**layout.unpack(v)), dtype=float))
    if not np.allclose(direct, F0 + np.tensordot(v, F, 1), rtol=1e-9, atol=1e-9 * (1 + np.abs(direct).max())):
        raise RuntimeError(f"internal error: the builder of {name} is not affine in its unknowns"
                           + (" (or its Kron terms are not the builder's)" if kr is not None else ""))  # fmt: skip
    G, kr_G = None, None
    if param is not None:
        G0, G, kr_G = _basis(layout, param, support, kron_param)
        if np.any(G0):
            raise RuntimeError(f"internal error: the parameter term of {name} has a constant part")
        direct = _sym(np.asarray(param(**layout.unpack(v)), dtype=float))
        if not np.allclose(direct, np.tensordot(v, G, 1), rtol=1e-9, atol=1e-9 * (1 + np.abs(direct).max())):
            raise RuntimeError(f"internal error: the parameter term of {name} is not linear in its unknowns")
    return AffineLMI(name, F0, F, G, kr, kr_G)


@dataclass(frozen=True)
class MarginLMI:
    """An LMI whose builder takes a margin ``m`` as well, affine in it: ``base + m * unit``."""

    base: AffineLMI
    unit: AffineLMI

    def at(self, m: float) -> AffineLMI:
        b, u = self.base, self.unit
        G = b.G if u.G is None else b.G + m * u.G
        kron = b.kron if u.kron is None else u.kron.scaled(m).plus(b.kron)
        return AffineLMI(b.name, b.F0 + m * u.F0, b.F + m * u.F, G, kron, b.kron_G)


def margin_lmi(
    name: str,
    layout: Layout,
    builder: Callable[..., np.ndarray],
    param: Callable[..., np.ndarray] | None = None,
    margin: Callable[..., np.ndarray] | None = None,
    support: np.ndarray | None = None,
    kron=None,
    kron_param=None,
) -> MarginLMI:
    """``builder(**unknowns) + m * margin(**unknowns)``: one extraction of each serves every margin ``m``.

    With ``kron`` (:func:`affine_lmi`), the margin term must not depend on that unknown (checked)."""
    base = affine_lmi(name, layout, builder, param, support, kron, kron_param)
    no_kron = None if kron is None else (kron[0], [])
    unit = (
        affine_lmi(name, layout, margin, support=support, kron=no_kron)
        if margin is not None
        else AffineLMI(name, 0 * base.F0, 0 * base.F)
    )
    return MarginLMI(base, replace(unit, kron=None))


#: a feasibility problem whose largest LMI has more rows than this in its triangle (k(k+1)/2; k = 45) is
#: given to SCS first when Clarabel was asked for: Clarabel factors each PSD cone as a dense block of that
#: many rows (measured, step 3 of a 24-state chain, k = 74: Clarabel 22 s and 1.35 GB, SCS 3.3 s and 0.56 GB)
LARGE_CONE = 1000
#: the iterations SCS is given when it is tried first on a large problem (then Clarabel); measured on the
#: 24-state chain: step 5 needs between 5000 and 10^4 at 1e-6, an infeasible (45) is reported after them (30 s)
SCS_FIRST_ITERS = 10_000
#: SCS's settings when it is tried first on a large problem: its point only starts the centring, and a point
#: that misses the LMIs by the solver's tolerance is repaired by phase 1 in numpy (whose Newton steps are
#: cheap since the Kronecker Hessian), so 1e-3 suffices (24-state chain, step 5: 17.8 s at 1e-6, 1.2 s at 1e-3,
#: the same design)
SCS_FIRST = {"max_iters": SCS_FIRST_ITERS, "eps_abs": 1e-3, "eps_rel": 1e-3}

#: a problem whose PSD cones hold more rows than this in all gets its start point from phase 1 in numpy where
#: the design knows a strictly feasible start for its fixed LMIs (step 5): measured, a 64-rule chain's (46)
#: 1.2-2.6 s with Clarabel (with cvxpy's compilation) against 0.15 s in numpy, a 24-state chain's 18 s with
#: SCS. (Sending step 3's heavy (45) to SCS first instead of Clarabel, 0.65 s against 1.4 s, gained nothing
#: in a whole design: the different start point cost the centring more Newton steps.)
HEAVY_CONES = 4000

#: the solver statuses that come with a point (which the design then checks in numpy)
SOLVED = ("optimal", "optimal_inaccurate")


@dataclass(frozen=True)
class SolveResult:
    status: str  # cvxpy's status, or "solver_error (...)"
    v: np.ndarray | None
    seconds: float
    rescaled: bool = False
    warned: tuple[str, ...] = ()
    solver: str = ""  # the solver that gave this answer

    @property
    def optimal(self) -> bool:
        return self.status == "optimal" and self.v is not None

    @property
    def infeasible(self) -> bool:
        return self.status in ("infeasible", "infeasible_inaccurate")

    @property
    def failed(self) -> bool:
        """Neither a point nor a certificate of infeasibility: a numerical failure of the solver."""
        return not self.infeasible and (self.v is None or self.status not in SOLVED)


class ConicProblem:
    """``minimise c^T v`` subject to LMIs, built once in cvxpy (a parameter ``p`` where an LMI has ``G``).

    :meth:`solve` counts the solves. A solver failure (an exception or a status that is neither
    a point nor a certificate of infeasibility) is retried once on rescaled data: every variable
    scaled to a unit column norm of the stacked LMI data and every LMI divided by its largest
    constant entry, which changes the numbers the solver sees but not the problem.
    """

    def __init__(self, layout: Layout, lmis: Sequence[AffineLMI], c: np.ndarray | None = None):
        self.layout = layout
        self.lmis = tuple(lmis)
        self.c = np.zeros(layout.size) if c is None else np.asarray(c, dtype=float)
        self.solves = 0
        self.seconds = 0.0
        self.notes: list[str] = []
        self._built: dict[bool, tuple] = {}

    def _build(self, rescale: bool):
        if rescale in self._built:
            return self._built[rescale]
        nv = self.layout.size
        cols = np.concatenate([L.F.reshape(nv, -1) for L in self.lmis], axis=1)
        d = 1.0 / np.maximum(np.linalg.norm(cols, axis=1), 1e-300) if rescale else np.ones(nv)
        w = cp.Variable(nv)
        p = cp.Parameter(nonneg=True, value=0.0)
        cons = []
        for L in self.lmis:
            k = L.k
            scale = 1.0 / max(np.abs(L.F0).max(), 1e-300) if rescale and np.any(L.F0) else 1.0
            Fm = (L.F.reshape(nv, -1).T * d) * scale
            expr = cp.reshape(Fm @ w, (k, k), order="C") + L.F0 * scale
            if L.G is not None:
                Gm = (L.G.reshape(nv, -1).T * d) * scale
                expr = expr + p * cp.reshape(Gm @ w, (k, k), order="C")
            cons.append(expr << 0)
        prob = cp.Problem(cp.Minimize((self.c * d) @ w), cons)
        self._built[rescale] = (prob, w, p, d)
        return self._built[rescale]

    def _solve_once(self, solver: str, p: float, rescale: bool, settings: dict | None = None) -> SolveResult:
        prob, w, par, d = self._build(rescale)
        par.value = float(p)
        w.value = None
        t0 = time.perf_counter()
        self.solves += 1
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                prob.solve(solver=solver, **(SOLVER_SETTINGS[solver] | (settings or {})))
                status = str(prob.status)
            except cp.SolverError as exc:
                status = f"solver_error ({' '.join(str(exc).split())[:120]})"
        elapsed = time.perf_counter() - t0
        self.seconds += elapsed
        warned = tuple(sorted({str(wn.message).split(".")[0] for wn in caught}))
        v = None if w.value is None else np.asarray(w.value, dtype=float) * d
        return SolveResult(status, v, elapsed, rescale, warned, solver)

    @property
    def heavy(self) -> bool:
        """Do the LMIs' PSD cones hold more than :data:`HEAVY_CONES` rows in all (many rules, or a large LMI)?"""
        return sum(L.k * (L.k + 1) // 2 for L in self.lmis) > HEAVY_CONES

    @property
    def large(self) -> bool:
        """Is the largest LMI beyond :data:`LARGE_CONE` rows of Clarabel's dense cone block?"""
        return max((L.k * (L.k + 1) // 2 for L in self.lmis), default=0) > LARGE_CONE

    def solve(self, solver: str, p: float = 0.0) -> SolveResult:
        """Solve with ``solver``; a large problem asked of Clarabel goes to SCS first (and to Clarabel
        when SCS fails): the solves only give start points, which the design checks and centres in numpy."""
        if solver == "CLARABEL" and self.large:
            # a few thousand iterations find a point when there is one with margin; a problem SCS
            # cannot settle in 10^4 (badly scaled, or infeasible) goes to Clarabel instead of
            # running to 10^5 (minutes)
            res = self._solve_once("SCS", p, rescale=False, settings=SCS_FIRST)
            # an inaccurate point goes to Clarabel; an inaccurate infeasibility is kept: what follows an
            # infeasible (45) or (46) is a search whose bounds are solves of their own (Clarabel took
            # 105 s and 2.2 GB to fail numerically on the 24-state chain's (45) at sigma = 1)
            if res.status in ("optimal", "infeasible", "infeasible_inaccurate"):
                k = max(L.k for L in self.lmis)
                self.notes.append(f"SCS gave this answer: an LMI of size {k} is a dense block of {k * (k + 1) // 2} "
                                  f"rows in Clarabel's KKT system (more than {LARGE_CONE})")  # fmt: skip
                return res
        return self._solve_with(solver, p)

    def numpy_first(self, soft: int, v0: np.ndarray, hard=()) -> SolveResult | None:
        """A heavy problem's start point by :func:`phase1` in numpy instead of a conic solver: its first
        ``soft`` LMIs are the soft ones, the rest (with ``hard``) must hold strictly at ``v0``; the parameter
        ``p`` is 0. Phase 1 either finds a strictly feasible point or proves that none exists (the duality
        bound); with the Kronecker Hessian its Newton steps cost less than a conic solver's iterations on a
        dense PSD cone (24-state chain: an infeasible (45) 30 s with SCS, a feasible (46) 1.2-18 s). None when
        it fails (the conic solvers then)."""
        t0 = time.perf_counter()
        try:
            v = phase1(self.lmis[:soft], list(self.lmis[soft:]) + list(hard), v0)
        except CentringError:
            return None
        elapsed = time.perf_counter() - t0
        self.seconds += elapsed
        rows = sum(L.k * (L.k + 1) // 2 for L in self.lmis)
        self.notes.append(f"phase 1 in numpy gave this answer ({'a point' if v is not None else 'infeasible'}, "
                          f"{elapsed:.2g} s): {len(self.lmis)} LMIs, {rows} rows of PSD cones for a conic solver")  # fmt: skip
        return SolveResult("optimal" if v is not None else "infeasible", v, elapsed, solver="phase 1 (numpy)")

    def _solve_with(self, solver: str, p: float) -> SolveResult:
        res = self._solve_once(solver, p, rescale=False)
        if res.failed:
            res2 = self._solve_once(solver, p, rescale=True)
            return SolveResult(
                res2.status, res2.v, res.seconds + res2.seconds, True, res.warned + res2.warned
            )
        return res


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
            iu, ju = np.triu_indices(n)
            w = np.where(iu == ju, 0.5, 1.0)
            X = ((C[:, :, iu, ju] + C[:, :, ju, iu]) * w).ravel()  # (g, nd, n(n+1)/2)
            rows = self.pos[start : start + len(iu)]
            nf = Hm.shape[0]
            at = (ip[:, :, None] * nf + rows[None, None, :]).ravel()
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
#: point returned is the same (64-rule chain: 319 -> ... Newton steps in two centrings)
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
