"""LMIs as affine maps of one variable vector and their cvxpy form.

Every LMI of the design is written once, as a numpy function of plain matrices (the builders of
:mod:`fte_casadi.design.core._certify`, which also compute the certificates). For a solve, the
unknowns are packed into one vector ``v`` (:class:`Layout`) and the builder is evaluated at
``v = 0`` and at the unit vectors, which gives the LMI exactly as ``F(v) = F0 + sum_l v_l F_l``
(the builders are affine in the unknowns; :func:`affine_lmi` checks it at a random point).
cvxpy then receives one precomputed affine expression per LMI, which it compiles in a few
milliseconds; a scalar parameter ``p`` (the observer decay rate) may enter as ``p * G(v)``, which
keeps the problem DPP so that re-solving for another ``p`` does not re-canonicalise it.

The Newton methods that centre the solver's point and decide feasibility in numpy are in
:mod:`fte_casadi.design.core._barrier`.
"""

from __future__ import annotations

import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..._text import shorten
from ...errors import CentringError as CentringError
from ._linalg import sym as _sym

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
    "CentringError",
    "SOLVER_SETTINGS",
    "positive",
]

#: settings passed explicitly to every solve. The solves are feasibility problems whose point only
#: has to lie strictly inside LMIs with half the margins they were posed with (checked with numpy
#: afterwards), so the first-order SCS is asked for 1e-6, not for an interior-point accuracy.
#: Clarabel factors its KKT system with faer's supernodal LDL: a PSD cone of size k is a dense block
#: of k(k+1)/2 rows there, which the default QDLDL factors as if sparse (several times slower on
#: the larger members of the chain family: docs/benchmarks.md); one thread, so that a run repeats
#: itself exactly.
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

#: SCS's status when it stopped on a SIGINT (its own handler catches the signal while it solves)
SCS_SIGINT = -5


def cvxpy_solver(name: str):
    """What to pass cvxpy's ``solve(solver=...)`` for ``name``: the name, except for SCS, which catches a SIGINT
    itself while it solves and reports it as a solver failure (cvxpy's ``SolverError``, which the design would
    answer by trying the other solver): SCS is called through a subclass of cvxpy's interface that raises the
    Ctrl-C as ``KeyboardInterrupt`` (:func:`fte_casadi._interrupt.interrupted`)."""
    if name != "SCS":
        return name
    from cvxpy.reductions.solvers.conic_solvers.scs_conif import SCS

    from ..._interrupt import interrupted

    class InterruptibleSCS(SCS):
        def name(self) -> str:
            return "SCS_FTE"  # cvxpy refuses a custom solver under a built-in name

        def solve_via_data(self, data, warm_start, verbose, solver_opts, solver_cache=None):
            results = super().solve_via_data(data, warm_start, verbose, solver_opts, solver_cache)
            if (results.get("info") or {}).get("status_val") == SCS_SIGINT:
                raise interrupted()
            return results

    return InterruptibleSCS()


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
        # per unknown: its name, its slice of v, and how it is laid out (unpack is called once per unknown and
        # builder when an LMI's coefficients are extracted: thousands of times per design)
        self._slots = tuple((var.name, slice(int(a), int(a) + var.size), var.shape, self._triu.get(var.name))
                            for var, a in zip(self.vars, self.offsets[:-1]))  # fmt: skip

    def unpack(self, v: np.ndarray) -> dict:
        v = np.asarray(v, dtype=float)
        out = {}
        for name, sl, shape, tri in self._slots:
            chunk = v[sl]
            if tri is not None:
                M = np.zeros(shape)
                M[tri] = chunk
                M[tri[1], tri[0]] = chunk  # the lower triangle mirrors the upper
                out[name] = M
            elif shape == ():
                out[name] = float(chunk[0])
            else:
                out[name] = chunk.reshape(shape)
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


def positive(layout: Layout, name: str) -> AffineLMI:
    """``-X < 0`` for the symmetric unknown ``name`` of ``layout`` (``X > 0``)."""
    sl = layout.index(name)
    n = layout.vars[[v.name for v in layout.vars].index(name)].shape[0]
    F = np.zeros((layout.size, n, n))
    iu, ju = np.triu_indices(n)
    for q, (a, b) in enumerate(zip(iu, ju)):
        F[sl.start + q, a, b] = F[sl.start + q, b, a] = -1.0
    return AffineLMI(f"{name} > 0", np.zeros((n, n)), F)


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
        import cvxpy as cp  # here, not at the module's import: a command that solves nothing starts without it

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
        import cvxpy as cp

        prob, w, par, d = self._build(rescale)
        par.value = float(p)
        w.value = None
        t0 = time.perf_counter()
        self.solves += 1
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            try:
                prob.solve(solver=cvxpy_solver(solver), **(SOLVER_SETTINGS[solver] | (settings or {})))
                status = str(prob.status)
            except cp.SolverError as exc:
                status = f"solver_error ({shorten(exc, 120)})"
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

    def _solve_with(self, solver: str, p: float) -> SolveResult:
        res = self._solve_once(solver, p, rescale=False)
        if res.failed:
            res2 = self._solve_once(solver, p, rescale=True)
            return SolveResult(
                res2.status, res2.v, res.seconds + res2.seconds, True, res.warned + res2.warned
            )
        return res
