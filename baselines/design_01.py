"""The 0.1 design: the design formulation of fte_casadi 0.1, kept only as the baseline of ``fte bench``.

Today's design is :mod:`fte_casadi.design.core._conditioned`; the formulation below is not
unique (N, Q_i, Y_j are free at its optimum, so different machines land on different points),
needs about 30 solves (a grid over scales of Pbar x decay rates x a bisection on theta) and
takes seconds. ``fte bench`` runs :func:`design_01` beside today's design in the same process
so that the speed-up it reports is measured, not remembered (the numbers measured are also kept in
docs/benchmarks.md). Nothing else uses this module. It lives in the source repository, not in the package
or its wheel: ``fte bench`` loads it from a checkout (:func:`fte_casadi.bench._design.design_01_baseline`).

Corrections of the printed LMIs are listed in :mod:`fte_casadi.design.core._certify`.

Two variants
------------
``paper``
    The problem as printed (with the corrections). Step 3: feasibility of (45) for ``X > 0``,
    ``Y_j`` (no objective). Step 5: ``min theta`` subject to (46), (55), (64), ``Pbar > 0``.
    Strict inequalities become ``<= -1e-7 I``. Because ``Cbar J1 = 0``, (20) forces
    ``J1^T Pbar J1 = 0`` and ``min theta`` drives Pbar towards singular: this variant is
    ill-conditioned by construction, and its result is only ever reported with the
    certificate recomputed at the returned point.

``conditioned`` (default)
    The same certificate (every printed LMI is imposed unchanged), posed so that solvers
    return usable gains:

    * step 3: ``X >= beta I`` (beta = min(half the largest feasible, BETA_CAP = 0.3)) and
      ``min t`` with ``||Y_j||_2 <= t`` (Schur form), so that ``||K_j|| <= t / beta`` stays
      implementable (three-tank: max|K| ~ 1.1e3 instead of ~2.8e3 at beta = 0.1);
    * step 5: ``c I <= Pbar <= kappa c I`` (kappa = 1e4 bounds cond(Pbar)) with the scale ``c``
      the largest of :data:`C_SCALES` that certifies. ``c = 1`` is not always possible: for the
      three-tank, P = X^-1 is ~1e-2 along the slow unmeasured tank, so ``-sigma P P`` cannot
      dominate ``W^T T^T Pbar T W`` when ``Pbar >= I`` and the observer stays slow (Clarabel
      then reports solver_error rather than infeasible). ``||Q_i||_2 <= q`` is minimised, and
      ``theta`` is *fixed* in each solve and found by bisection in log scale between ``c^2`` (a
      lower bound: (55) implies ``theta > lambda_min(J1^T Pbar J1)^2 >= c^2``) and a value always
      feasible for (55), (64); the final solve uses ``theta_slack * theta_min`` which buys smaller
      gains (minimising theta directly made Clarabel stall). With theta fixed, (55) and (64) are
      imposed in the congruent balanced form ``[[-sqrt(theta) I, E^T], [E, -sqrt(theta) I]]``;
    * a decay-rate term ``2 alpha Pbar`` in the (3,3) block of (46): ``Pbar R_i + R_i^T Pbar
      < -2 alpha Pbar`` so every R_i has decay rate at least alpha (the three-tank
      observer is otherwise very slow). The recorded certificate is the printed (46);
    * margins per diagonal block, relative to that block's own scale (``-gamma1^2 I`` is
      only ``-1e-4`` for the manipulator, so one uniform margin would fail).

    Every accept/retry decision (step 3, the search over c and alpha, each bisection step) uses
    the numpy certificate of :mod:`fte_casadi.design.core._certify` at the returned point, never the
    solver status alone ("optimal_inaccurate" points are kept only when they certify). On
    failure step 5 is retried with alpha / 2, alpha / 4, 0 and then with SCS; SCS runs with capped
    iterations and a wall-clock budget (:data:`BUDGET_S`) so that it certifies or fails fast.
    cvxpy's "Solution may be inaccurate" warnings are caught and reported in the notes.
"""

from __future__ import annotations

import time
import warnings
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np

from fte_casadi.design import Augmented
from fte_casadi.design.core._certify import ts_max
from fte_casadi.design.core._linalg import sym as _sym
from fte_casadi.design.core._lmis import block_sizes, lmi45, lmi46, lmi46_terms, lmi55, lmi64
from fte_casadi.design.core._sdp import SOLVED
from fte_casadi.errors import InfeasibleDesignError

__all__ = ["design_01"]

#: solver settings, passed explicitly to every solve
SOLVER_SETTINGS = {
    "CLARABEL": {
        "max_iter": 300,
        "time_limit": 3.0,
        "tol_feas": 1e-9,
        "tol_gap_abs": 1e-9,
        "tol_gap_rel": 1e-9,
    },
    # capped: SCS's first-order iterations rarely reach a certifiable point on these problems,
    # so fail fast (every SCS point is checked by the numpy certificate anyway)
    "SCS": {"max_iters": 20_000, "time_limit_secs": 1.5, "eps_abs": 1e-7, "eps_rel": 1e-7},
}
#: bound on cond(Pbar) in the conditioned variant (c I <= Pbar <= KAPPA c I)
KAPPA = 1e4
#: wall-clock budget (s) of one conditioned step 5 per solver; past it no new solve starts
#: (SCS rarely reaches a certifiable point here and each solve runs to its time limit)
BUDGET_S = {"SCS": 10.0}
#: scales c tried, in this order, in the normalisation c I <= Pbar <= KAPPA c I of step 5
C_SCALES = (1.0, 0.3, 0.1, 0.03, 0.01, 0.003, 0.001)
#: upper cap of the lower bound beta on X in step 3 (a larger X makes P = X^-1 small and step 5 hard)
BETA_CAP = 0.3


@dataclass
class Step3:
    X: np.ndarray
    Y: list
    status: str
    solver_s: float
    notes: list = field(default_factory=list)


@dataclass
class Step5:
    Pbar: np.ndarray
    Q: list
    N: np.ndarray
    theta: float
    status: str
    solver_s: float
    alpha: float
    notes: list = field(default_factory=list)


def _margin(sizes, values):
    return np.diag(np.concatenate([np.full(b, v) for b, v in zip(sizes, values)]))


def _solve(prob: cp.Problem, solver: str, warned: list | None = None) -> tuple[str, float]:
    """Solve with the settings of :data:`SOLVER_SETTINGS`; solver warnings (cvxpy's "Solution may
    be inaccurate") are caught and appended to ``warned`` instead of reaching the terminal."""
    t0 = time.perf_counter()
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            prob.solve(solver=solver, **SOLVER_SETTINGS[solver])
            status = prob.status
        except cp.SolverError as exc:
            status = f"solver_error ({exc})"
    if warned is not None:
        for w in caught:
            msg = str(w.message).split(".")[0]
            warned.append(f"{solver} warned: {msg!r} (accepted only where the numpy certificate holds)")
    return str(status), time.perf_counter() - t0


def _lmi45(aug: Augmented, i: int, X, Y, sigma, gamma, gamma1):
    # Written out again, on purpose, as numpy in certify.lmi45: the certificate must not reuse
    # the expression the solver was given, so a slip in one is caught by the other.
    n, p, ld = aug.n, aug.p, aug.ld
    A, B = aug.Abar[i][:n, :n], aug.Bbar[i][:n]
    W, G = aug.Wbar[i][:n], aug.Gbar[i][:n]
    C, Bd = aug.Cbar[:, :n], aug.Bdbar[i][:n]
    Psi = A @ X + X @ A.T + B @ Y + Y.T @ B.T + sigma * np.eye(n)
    XW = X @ W.T + Y.T @ G.T
    Z = np.zeros
    L = cp.bmat([
        [Psi, XW, X @ C.T, Bd],
        [XW.T, -X, Z((n, p)), Z((n, ld))],
        [C @ X, Z((p, n)), -np.eye(p), Z((p, ld))],
        [Bd.T, Z((ld, n)), Z((ld, p)), (gamma1**2 - gamma**2) * np.eye(ld)],
    ])  # fmt: skip
    return _sym(L)


def _check3(aug, X, Y, sigma, gamma, gamma1) -> float:
    """Largest eigenvalue of (45) over all (i, j) and of -X, recomputed with numpy."""
    X = np.asarray(X)
    Y = [np.asarray(Yj) for Yj in Y]
    if not (np.all(np.isfinite(X)) and all(np.all(np.isfinite(Yj)) for Yj in Y)):
        return float("inf")
    w = [
        float(np.linalg.eigvalsh(lmi45(aug, i, X, Yj, sigma, gamma, gamma1))[-1])
        for i in range(aug.r)
        for Yj in Y
    ]
    return max(w + [-float(np.linalg.eigvalsh(_sym(X))[0])])


def solve_step3(aug: Augmented, params: dict, variant: str, solver: str) -> Step3:
    """Step 3: LMI (45) (or (78)) for X, Y_j."""
    n, m, r = aug.n, aug.m, aug.r
    s, g, g1 = params["sigma"], params["gamma"], params["gamma1"]
    X = cp.Variable((n, n), symmetric=True)
    Y = [cp.Variable((m, n)) for _ in range(r)]
    sizes = block_sizes(aug)["45"]
    cons45 = lambda D: [_lmi45(aug, i, X, Y[j], s, g, g1) << -D for i in range(r) for j in range(r)]  # noqa: E731
    notes: list[str] = []
    warned: list[str] = []
    if variant == "paper":
        prob = cp.Problem(cp.Minimize(0), [X >> 1e-7 * np.eye(n)] + cons45(1e-7 * np.eye(sum(sizes))))
        status, dt = _solve(prob, solver, warned)
    else:
        D = _margin(sizes, [1e-3 * s, 0.0, 1e-3, 1e-3 * (g**2 - g1**2)])
        # (a) the largest beta with X >= beta I; (b) min t with ||Y_j||_2 <= t at X >= beta_max / 2
        b = cp.Variable()
        prob = cp.Problem(cp.Maximize(b), [X >> b * np.eye(n), b <= 2.0] + cons45(D))
        status, dt = _solve(prob, solver, warned)
        if status in SOLVED and b.value is not None and b.value > 0:
            beta = min(0.5 * float(b.value), BETA_CAP)
            t = cp.Variable()
            cons = [X >> beta * np.eye(n)] + cons45(D)
            cons += [cp.bmat([[t * np.eye(m), Yj], [Yj.T, t * np.eye(n)]]) >> 0 for Yj in Y]
            prob = cp.Problem(cp.Minimize(t), cons)
            status, dt2 = _solve(prob, solver, warned)
            dt += dt2
            notes.append(
                f"step 3: X >= {beta:.4g} I (half the largest feasible, at most {BETA_CAP:g}), min t with ||Y_j||_2 <= t"
            )
        elif status in SOLVED:
            status = "infeasible (no X > 0)"
    if variant != "paper" and status in SOLVED and X.value is not None:
        worst = _check3(aug, X.value, [Yj.value for Yj in Y], s, g, g1)
        if not worst < 0:
            status = f"{status}, but the numpy certificate of (45) fails (largest eigenvalue {worst:.3g})"
    notes += sorted(set(warned))
    if "numpy certificate" in status:
        raise InfeasibleDesignError(
            f"LMI (45): {solver} returned a point that does not satisfy it ({status}); use solver='CLARABEL'"
        )
    if status not in SOLVED or X.value is None:
        raise InfeasibleDesignError(
            f"LMI (45) is infeasible: gamma = {g:g} is below what the plant allows with gamma1 = {g1:g}, "
            f"sigma = {s:g}; raise gamma or lower gamma1 or sigma ({solver}: {status})"
        )
    return Step3(np.asarray(X.value), [np.asarray(Yj.value) for Yj in Y], status, dt, notes)


class _Step5Problem:
    """Step 5 as a cvxpy problem with theta (and alpha) as parameters, built once."""

    def __init__(self, aug, params, P, K, T, variant, kappa=1e4):
        n, p, lf, ld, nbar, r = aug.n, aug.p, aug.lf, aug.ld, aug.nbar, aug.r
        s, g1 = params["sigma"], params["gamma1"]
        g2 = params.get("gamma2", params["gamma"])
        self.warned: list[str] = []
        self.Pbar = Pb = cp.Variable((nbar, nbar), symmetric=True)
        self.Q = Q = [cp.Variable((nbar, p)) for _ in range(r)]
        self.N = N = cp.Variable((lf, p))
        self.theta = cp.Parameter(nonneg=True, value=1.0) if variant != "paper" else cp.Variable()
        self.alpha = cp.Parameter(nonneg=True, value=0.0)
        self.rt = cp.Parameter(nonneg=True, value=1.0) if variant != "paper" else None
        theta = self.theta
        sizes = block_sizes(aug)
        Pmin = float(np.linalg.eigvalsh(P)[0])
        cons = []
        if variant == "paper":
            e = 1e-7
            D46 = e * np.eye(sum(sizes["46"]))
            D55, D64 = e * np.eye(nbar + lf), e * np.eye(n + lf)
            cons.append(Pb >> e * np.eye(nbar))
            obj = cp.Minimize(theta)
        else:
            l2 = sizes["46"][3:]
            D46 = _margin(sizes["46"], [1e-3 * s * Pmin**2, 1e-3 * g1**2, 1e-6] + [1e-3 * g2**2] * len(l2))
            # balanced (55)/(64) with the margin relative to sqrt(theta): ||E||_2 <= (1 - 1e-3) sqrt(theta)
            D55 = 1e-3 * self.rt * np.eye(sum(sizes["55"]))
            D64 = 1e-3 * self.rt * np.eye(sum(sizes["64"]))
            self.q = q = cp.Variable()
            # the scale c of Pbar is a parameter (c <= 1 keeps theta_hi, computed for c = 1, feasible)
            self.c = c = cp.Parameter(pos=True, value=1.0)
            cons += [Pb >> c * np.eye(nbar), Pb << kappa * c * np.eye(nbar)]
            cons += [cp.bmat([[q * np.eye(nbar), Qi], [Qi.T, q * np.eye(p)]]) >> 0 for Qi in Q]
            obj = cp.Minimize(q)
        TPT = T.T @ Pb @ T
        Z = np.zeros
        for i in range(r):
            Ab, Cb = aug.Abar[i], aug.Cbar
            for j in range(r):
                c = lmi46_terms(aug, i, K[j])
                C, De, Be, Ge, Wk, Wbk, Gbe, M, Mb = (
                    c[k] for k in ("C", "De", "Be", "Ge", "Wk", "Wbk", "Gbe", "M", "Mb")
                )
                T11 = -s * P @ P + Wbk.T @ TPT @ Wbk
                T13 = -P @ Be - Wk.T @ P @ Ge - Wbk.T @ TPT @ Gbe + C.T @ De
                PTA = Pb @ T @ Ab
                QC = Q[i] @ Cb
                T33 = (
                    PTA
                    + PTA.T
                    - QC
                    - QC.T
                    + Ge.T @ P @ Ge
                    + Gbe.T @ TPT @ Gbe
                    + De.T @ De
                    + 2 * self.alpha * Pb
                )
                rows = [
                    [T11, Z((n, ld)), T13],
                    [Z((ld, n)), -(g1**2) * np.eye(ld), Z((ld, nbar))],
                    [T13.T, Z((nbar, ld)), T33],
                ]
                l2 = M.shape[1]
                if l2:
                    T14 = Wk.T @ P @ M + Wbk.T @ TPT @ Mb
                    T34 = -Ge.T @ P @ M - Gbe.T @ TPT @ Mb
                    T44 = M.T @ P @ M + Mb.T @ TPT @ Mb - g2**2 * np.eye(l2)
                    rows[0].append(T14)
                    rows[1].append(Z((ld, l2)))
                    rows[2].append(T34)
                    rows.append([T14.T, Z((l2, ld)), T34.T, T44])
                cons.append(_sym(cp.bmat(rows)) << -D46)
            E64 = aug.J1.T @ T.T @ Pb @ T @ aug.Wbar[i]
            cons.append(self._theta_lmi(E64, n, lf) << -D64)
        E55 = aug.J1.T @ T.T @ Pb - N @ aug.Cbar
        cons.append(self._theta_lmi(E55, nbar, lf) << -D55)
        self.prob = cp.Problem(obj, cons)
        self.theta_hi = float((kappa * max(1.0, max(np.linalg.norm(T @ W, 2) for W in aug.Wbar))) ** 2 * 1.01)

    def _theta_lmi(self, E, a, b):
        """``[[-theta I, E^T], [E, -I]]``; with theta fixed, the congruent balanced form
        ``[[-sqrt(theta) I, E^T], [E, -sqrt(theta) I]]`` (same inertia, entries of the size of Pbar
        instead of theta ~ Pbar^2, which made Clarabel fail numerically)."""
        if isinstance(self.theta, cp.Variable):
            return _sym(cp.bmat([[-self.theta * np.eye(a), E.T], [E, -np.eye(b)]]))
        return _sym(cp.bmat([[-self.rt * np.eye(a), E.T], [E, -self.rt * np.eye(b)]]))

    def solve(self, solver, theta=None, alpha=0.0, c=None):
        if c is not None:
            self.c.value = c
        if theta is not None:
            self.theta.value = theta
            if self.rt is not None:
                self.rt.value = float(np.sqrt(theta))
        self.alpha.value = alpha
        self.Pbar.value = None  # no stale values from an earlier solve after a solver error
        status, dt = _solve(self.prob, solver, self.warned)
        ok = status in SOLVED and self.Pbar.value is not None
        return ok, status, dt

    def point(self):
        th = float(self.theta.value)
        return (
            np.asarray(self.Pbar.value),
            [np.asarray(Qi.value) for Qi in self.Q],
            np.asarray(self.N.value),
            th,
        )


def _check5(aug, params, P, K, T, point, alpha) -> tuple[bool, str]:
    """The numpy certificate of step 5 at ``point``: printed (46), (55), (64), Pbar > 0, R_i Hurwitz.

    Returns (holds, reason). The decay rate is checked loosely (max Re eig(R_i) < -alpha / 2):
    the solver may return a point on the boundary of the alpha-constraint.
    """
    Pb, Q, N, th = point
    if not all(np.all(np.isfinite(M)) for M in [Pb, N, *Q]) or not np.isfinite(th):
        return False, "non-finite point"
    s, g1 = params["sigma"], params["gamma1"]
    g2 = params.get("gamma2", params["gamma"])
    r = aug.r
    worst = {
        "46": max(
            float(np.linalg.eigvalsh(lmi46(aug, i, K[j], P, T, Pb, Q[i], s, g1, g2))[-1])
            for i in range(r)
            for j in range(r)
        ),  # fmt: skip
        "55": float(np.linalg.eigvalsh(lmi55(aug, T, Pb, N, th))[-1]),
        "64": max(float(np.linalg.eigvalsh(lmi64(aug, i, T, Pb, th))[-1]) for i in range(r)),
    }
    bad = [f"({k}) max eig {v:.2g}" for k, v in worst.items() if not v < 0]
    if not np.linalg.eigvalsh(_sym(Pb))[0] > 0:
        bad.append("Pbar not > 0")
    else:
        L1 = [np.linalg.solve(Pb, Qi) for Qi in Q]
        re = max(float(np.max(np.linalg.eigvals(T @ aug.Abar[i] - L1[i] @ aug.Cbar).real)) for i in range(r))
        if not re < -0.5 * alpha:
            bad.append(f"max Re eig(R_i) = {re:.3g}" + (f" (alpha = {alpha:.3g})" if alpha > 0 else ""))
    return not bad, "; ".join(bad)


def solve_step5(aug, params, P, K, T, variant, solver, alpha=0.0, theta_slack=2.0, bisect_iters=12) -> Step5:
    """Step 5: (46), (55), (64) (or (79)-(81)) for Pbar, Q_i, N, theta.

    Conditioned variant: a solve is *accepted* only when its numpy certificate holds
    (:func:`_check5`), whatever the solver's status says; the bisection on theta uses the same
    test. Pbar is normalised as ``c I <= Pbar <= kappa c I`` with the scale ``c`` free (the
    three-tank needs ``c`` ~ 1e-2: with ``Pbar >= I`` the ``-sigma P P`` block cannot dominate
    ``W^T T^T Pbar T W`` along the slow unmeasured tank and the observer stays slow).
    """
    notes: list[str] = []
    if variant == "paper":
        prob = _Step5Problem(aug, params, P, K, T, variant)
        ok, status, dt = prob.solve(solver)
        notes += prob.warned
        if not ok:
            raise InfeasibleDesignError(
                f"LMI (46) with (55), (64) is infeasible as printed ({solver}: {status}); the paper variant is "
                "ill-conditioned (equality (20) cannot hold with Pbar > 0): use variant='conditioned', or raise "
                "gamma1 or sigma"
            )
        Pb, Q, N, th = prob.point()
        return Step5(Pb, Q, N, th, status, dt, 0.0, notes)
    prob = _Step5Problem(aug, params, P, K, T, variant, kappa=KAPPA)
    total = 0.0
    t_start = time.perf_counter()

    def over_budget(sv):
        return sv in BUDGET_S and time.perf_counter() - t_start > BUDGET_S[sv]

    def attempt(sv, theta, a, c):
        nonlocal total
        if over_budget(sv):
            return False, f"{sv} time budget of {BUDGET_S[sv]:g} s for step 5 exhausted"
        ok, status, dt = prob.solve(sv, theta, a, c)
        total += dt
        if not ok:
            return False, status
        holds, why = _check5(aug, params, P, K, T, prob.point(), a)
        return holds, status if holds else f"{status}, but the numpy certificate fails: {why}"

    solvers = [solver] + (["SCS"] if solver != "SCS" else [])
    alphas = [alpha] + ([alpha / 2, alpha / 4, 0.0] if alpha > 0 else [])
    ok = False
    for sv in solvers:
        for a in alphas:
            for c in C_SCALES:
                ok, status = attempt(sv, prob.theta_hi, a, c)
                if ok:
                    break
            if ok:
                break
            notes.append(
                f"step 5 with alpha = {a:g} ({sv}) rejected for every scale c in {C_SCALES}: {status}"
            )
        if ok:
            break
    if not ok:
        notes_txt = "; ".join(notes[-3:])
        if over_budget(sv):
            raise InfeasibleDesignError(
                f"step 5: {sv} returned no point whose numpy certificate of (46), (55), (64) holds within its "
                f"time budget of {BUDGET_S[sv]:g} s ({notes_txt}); use solver='CLARABEL'"
            )
        raise InfeasibleDesignError(
            f"LMI (46) is infeasible together with c I <= Pbar <= {KAPPA:g} c I for the gains K_j of step 3, or no "
            f"solver returned a point whose numpy certificate holds ({notes_txt}); raise gamma1 or sigma (the "
            "-sigma P P block must dominate the diffusion) or lower alpha"
            + (", or use solver='CLARABEL'" if solver == "SCS" else ""),
        )
    if c != 1.0:
        notes.append(f"step 5: Pbar scale c = {c:g} (c I <= Pbar <= {KAPPA:g} c I; the largest c of {C_SCALES} "
                     "that certifies: with Pbar >= I the -sigma P P block cannot dominate W^T T^T Pbar T W)")  # fmt: skip
    if a != alpha or sv != solver:
        notes.append(f"step 5 solved with alpha = {a:g} using {sv}")
    best = prob.point()
    lo, hi = 2 * np.log10(c), np.log10(prob.theta_hi)  # (55): theta > lambda_min(J1^T Pbar J1)^2 >= c^2
    for _ in range(bisect_iters):
        if over_budget(sv):
            notes.append(f"step 5: bisection on theta stopped early ({sv} time budget of {BUDGET_S[sv]:g} s)")
            break
        mid = 0.5 * (lo + hi)
        ok, _status = attempt(sv, 10**mid, a, c)
        if ok:
            hi, best = mid, prob.point()
        else:
            lo = mid
    theta_min = 10**hi
    theta = min(theta_min * theta_slack, prob.theta_hi)
    ok, status = attempt(sv, theta, a, c)
    if ok:
        best = prob.point()
    else:
        notes.append(
            f"step 5 at theta = {theta:.4g} rejected ({status}); using the certified point at theta = {theta_min:.4g}"
        )
        status = "certified at theta_min"
    Pb, Q, N, th = best
    notes.append(f"step 5: theta by bisection (a point counts as feasible only if its numpy certificate holds), "
                 f"theta_min = {theta_min:.4g} (to 1 part in {10 ** (hi - lo):.3g}), used theta = {th:.4g}")  # fmt: skip
    notes += sorted(set(prob.warned))
    return Step5(Pb, Q, N, th, status, total, a, notes)


def _default_alpha_step5(ts, aug, params, P, K, T, solver):
    """Step 5 with the 0.1 default decay rate ``a0 = max(0.05 rho(A), 0.4 s_cl)``, trying a0 and 2 a0."""
    n = aug.n
    rho = max(float(np.max(np.abs(np.linalg.eigvals(lm.A)))) for lm in ts.local_models)
    s_cl = -max(float(np.max(np.linalg.eigvals(aug.Abar[i][:n, :n] + aug.Bbar[i][:n] @ Kj).real))
                for i in range(aug.r) for Kj in K)  # fmt: skip
    a0 = max(0.05 * rho, 0.4 * max(s_cl, 0.0))
    best, best_ts, err = None, -1.0, None
    for a in (a0, 2 * a0):
        try:
            s5 = solve_step5(aug, params, P, K, T, "conditioned", solver, alpha=a)
        except InfeasibleDesignError as exc:
            err = exc
            if "time budget" in str(exc):
                break
            continue
        R = [T @ aug.Abar[i] - np.linalg.solve(s5.Pbar, s5.Q[i]) @ aug.Cbar for i in range(aug.r)]
        t = ts_max(R)
        if t > best_ts:
            best, best_ts = s5, t
    if best is None:
        raise err
    return best


def design_01(ts, solver: str = "CLARABEL") -> dict:
    """The 0.1 conditioned design of a T-S model with the plant's default parameters, and its certificate."""
    from fte_casadi.design import augment, uio_gain
    from fte_casadi.design.core._certify import certificate

    defaults = {"gamma": 1.0, "gamma1": 0.5, "sigma": 1.0, "delta": 1e-4, "epsilon": 1e-4}
    params = {k: float(ts.plant.design_defaults.get(k, v)) for k, v in defaults.items()}
    aug = augment(ts.local_models, ts.C, ts.Df)
    H, T = uio_gain(aug)
    s3 = solve_step3(aug, params, "conditioned", solver)
    P = np.linalg.inv(s3.X)
    K = [Y @ P for Y in s3.Y]
    s5 = _default_alpha_step5(ts, aug, params, P, K, T, solver)
    L1 = [np.linalg.solve(s5.Pbar, Q) for Q in s5.Q]
    R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
    point = dict(X=s3.X, K=K, P=P, T=T, Pbar=s5.Pbar, Q=s5.Q, N=s5.N, theta=s5.theta, R=R, L1=L1)
    return {"checks": certificate(aug, point, params), "K": K, "L1": L1, "N": s5.N, "alpha": s5.alpha}
