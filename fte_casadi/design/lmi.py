"""The LMI design of Section 4.3 (Theorems 3/4; Theorem 5 when the diffusion carries u, f or d2).

Corrections of the printed LMIs are listed in :mod:`fte_casadi.design.certify`.

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

    * step 3: ``X >= beta I`` (beta = min(half the largest feasible, 0.1)) and ``min t`` with
      ``||Y_j||_2 <= t`` (Schur form), so that
      ``||K_j|| <= t / beta`` stays implementable;
    * step 5: ``I <= Pbar <= kappa I`` (normalisation ``c = 1``; ``kappa = 1e4`` bounds
      cond(Pbar)), ``||Q_i||_2 <= q`` minimised, and ``theta`` *fixed* in each solve and
      found by bisection in log scale between 1 (a lower bound: (55) implies
      ``theta > lambda_min(J1^T Pbar J1)^2 >= 1``) and a value always feasible for (55), (64);
      the final solve uses ``theta_slack * theta_min`` which buys smaller gains
      (minimising theta directly made Clarabel stall);
    * a decay-rate term ``2 alpha Pbar`` in the (3,3) block of (46): ``Pbar R_i + R_i^T Pbar
      < -2 alpha Pbar`` so every R_i has decay rate at least alpha (the three-tank
      observer is otherwise very slow). The recorded certificate is the printed (46);
    * margins per diagonal block, relative to that block's own scale (``-gamma1^2 I`` is
      only ``-1e-4`` for the manipulator, so one uniform margin would fail).

    On a solver failure step 5 is retried with alpha / 4, then alpha = 0, and then with
    SCS; what was done is appended to the status list.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import cvxpy as cp
import numpy as np

from ..errors import InfeasibleDesignError
from .augment import Augmented
from .certify import block_sizes, lmi46_terms

__all__ = ["Step3", "Step5", "solve_step3", "solve_step5", "SOLVER_SETTINGS"]

#: solver settings, passed explicitly to every solve
SOLVER_SETTINGS = {
    "CLARABEL": {
        "max_iter": 300,
        "time_limit": 3.0,
        "tol_feas": 1e-9,
        "tol_gap_abs": 1e-9,
        "tol_gap_rel": 1e-9,
    },
    "SCS": {"max_iters": 50_000, "eps_abs": 1e-8, "eps_rel": 1e-8},
}
OK = ("optimal", "optimal_inaccurate")
#: upper cap of the lower bound beta on X in step 3 (a larger X makes P = X^-1 small and step 5 hard)
BETA_CAP = 0.1


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


def _sym(E):
    return (E + E.T) / 2


def _margin(sizes, values):
    return np.diag(np.concatenate([np.full(b, v) for b, v in zip(sizes, values)]))


def _solve(prob: cp.Problem, solver: str) -> tuple[str, float]:
    t0 = time.perf_counter()
    try:
        prob.solve(solver=solver, **SOLVER_SETTINGS[solver])
        status = prob.status
    except cp.SolverError as exc:
        status = f"solver_error ({exc})"
    return str(status), time.perf_counter() - t0


def _lmi45(aug: Augmented, i: int, X, Y, sigma, gamma, gamma1):
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


def solve_step3(aug: Augmented, params: dict, variant: str, solver: str) -> Step3:
    """Step 3: LMI (45) (or (78)) for X, Y_j."""
    n, m, r = aug.n, aug.m, aug.r
    s, g, g1 = params["sigma"], params["gamma"], params["gamma1"]
    X = cp.Variable((n, n), symmetric=True)
    Y = [cp.Variable((m, n)) for _ in range(r)]
    sizes = block_sizes(aug)["45"]
    cons45 = lambda D: [_lmi45(aug, i, X, Y[j], s, g, g1) << -D for i in range(r) for j in range(r)]  # noqa: E731
    notes = []
    if variant == "paper":
        prob = cp.Problem(cp.Minimize(0), [X >> 1e-7 * np.eye(n)] + cons45(1e-7 * np.eye(sum(sizes))))
        status, dt = _solve(prob, solver)
    else:
        D = _margin(sizes, [1e-3 * s, 0.0, 1e-3, 1e-3 * (g**2 - g1**2)])
        # (a) the largest beta with X >= beta I; (b) min t with ||Y_j||_2 <= t at X >= beta_max / 2
        b = cp.Variable()
        prob = cp.Problem(cp.Maximize(b), [X >> b * np.eye(n), b <= 2.0] + cons45(D))
        status, dt = _solve(prob, solver)
        if status in OK and b.value is not None and b.value > 0:
            beta = min(0.5 * float(b.value), BETA_CAP)
            t = cp.Variable()
            cons = [X >> beta * np.eye(n)] + cons45(D)
            cons += [cp.bmat([[t * np.eye(m), Yj], [Yj.T, t * np.eye(n)]]) >> 0 for Yj in Y]
            prob = cp.Problem(cp.Minimize(t), cons)
            status, dt2 = _solve(prob, solver)
            dt += dt2
            notes.append(
                f"step 3: X >= {beta:.4g} I (half the largest feasible, at most {BETA_CAP:g}), min t with ||Y_j||_2 <= t"
            )
        elif status in OK:
            status = "infeasible (no X > 0)"
    if status not in OK or X.value is None:
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
        self.Pbar = Pb = cp.Variable((nbar, nbar), symmetric=True)
        self.Q = Q = [cp.Variable((nbar, p)) for _ in range(r)]
        self.N = N = cp.Variable((lf, p))
        self.theta = cp.Parameter(nonneg=True, value=1.0) if variant != "paper" else cp.Variable()
        self.alpha = cp.Parameter(nonneg=True, value=0.0)
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
            D55, D64 = _margin(sizes["55"], [1e-6, 1e-3]), _margin(sizes["64"], [1e-6, 1e-3])
            self.q = q = cp.Variable()
            cons += [Pb >> np.eye(nbar), Pb << kappa * np.eye(nbar)]
            cons += [cp.bmat([[q * np.eye(nbar), Qi], [Qi.T, q * np.eye(p)]]) >> 0 for Qi in Q]
            obj = cp.Minimize(q)
        TPT = T.T @ Pb @ T
        Z = np.zeros
        for i in range(r):
            Ab, Cb = aug.Abar[i], aug.Cbar
            for j in range(r):
                c = lmi46_terms(aug, i, K[j], P, T)
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
            cons.append(_sym(cp.bmat([[-theta * np.eye(n), E64.T], [E64, -np.eye(lf)]])) << -D64)
        E55 = aug.J1.T @ T.T @ Pb - N @ aug.Cbar
        cons.append(_sym(cp.bmat([[-theta * np.eye(nbar), E55.T], [E55, -np.eye(lf)]])) << -D55)
        self.prob = cp.Problem(obj, cons)
        self.theta_hi = float((kappa * max(1.0, max(np.linalg.norm(T @ W, 2) for W in aug.Wbar))) ** 2 * 1.01)

    def solve(self, solver, theta=None, alpha=0.0):
        if theta is not None:
            self.theta.value = theta
        self.alpha.value = alpha
        status, dt = _solve(self.prob, solver)
        ok = status in OK and self.Pbar.value is not None
        return ok, status, dt

    def point(self):
        th = float(self.theta.value)
        return (
            np.asarray(self.Pbar.value),
            [np.asarray(Qi.value) for Qi in self.Q],
            np.asarray(self.N.value),
            th,
        )


def solve_step5(aug, params, P, K, T, variant, solver, alpha=0.0, theta_slack=2.0, bisect_iters=10) -> Step5:
    """Step 5: (46), (55), (64) (or (79)-(81)) for Pbar, Q_i, N, theta."""
    notes: list[str] = []
    prob = _Step5Problem(aug, params, P, K, T, variant)
    if variant == "paper":
        ok, status, dt = prob.solve(solver)
        if not ok:
            raise InfeasibleDesignError(
                f"LMI (46) with (55), (64) is infeasible as printed ({solver}: {status}); the paper variant is "
                "ill-conditioned (equality (20) cannot hold with Pbar > 0): use variant='conditioned', or raise "
                "gamma1 or sigma"
            )
        Pb, Q, N, th = prob.point()
        return Step5(Pb, Q, N, th, status, dt, 0.0, notes)
    total = 0.0
    solvers = [solver] + (["SCS"] if solver != "SCS" else [])
    alphas = [alpha] + ([alpha / 4, 0.0] if alpha > 0 else [])
    for sv in solvers:
        for a in alphas:
            ok, status, dt = prob.solve(sv, prob.theta_hi, a)
            total += dt
            if ok:
                break
            notes.append(f"step 5 with alpha = {a:g} ({sv}) failed: {status}")
        if ok:
            break
    if not ok:
        raise InfeasibleDesignError(
            "LMI (46) is infeasible together with I <= Pbar <= 1e4 I for the gains K_j of step 3 "
            f"(last status: {status}); raise gamma1 or sigma (the -sigma P P block must dominate the diffusion)",
        )
    if a != alpha or sv != solver:
        notes.append(f"step 5 solved with alpha = {a:g} using {sv}")
    lo, hi = 0.0, np.log10(prob.theta_hi)
    for _ in range(bisect_iters):
        mid = 0.5 * (lo + hi)
        ok, status, dt = prob.solve(sv, 10**mid, a)
        total += dt
        lo, hi = (lo, mid) if ok else (mid, hi)
    theta_min = 10**hi
    theta = min(theta_min * theta_slack, prob.theta_hi)
    ok, status, dt = prob.solve(sv, theta, a)
    total += dt
    if not ok:
        notes.append(f"step 5 at theta = {theta:.4g} failed ({status}); using theta = {theta_min:.4g}")
        theta = theta_min
        ok, status, dt = prob.solve(sv, theta, a)
        total += dt
    Pb, Q, N, th = prob.point()
    notes.append(f"step 5: theta by bisection, theta_min = {theta_min:.4g} (to 1 part in "
                 f"{10 ** (1 / 2**bisect_iters * np.log10(prob.theta_hi)):.3g}), used theta = {th:.4g}")  # fmt: skip
    return Step5(Pb, Q, N, th, status, total, a, notes)
