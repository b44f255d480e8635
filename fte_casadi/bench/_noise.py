"""Where the conservatism with diffusion comes from (docs/design.md, "When the diffusion is the cause"): for one
plant, the largest scale s of its diffusion (every ``W_i`` times s; 1: as written) that each condition allows,
from the design's certificate down to what no controller can beat.

    fte bench --diffusion tests/plant_helicopter.py:helicopter
    fte bench --diffusion tests/plant_fjoint.py:fjoint --at '{"sigma": 0.35}'

The optional JSON sets the design parameters (else the ones the design at the defaults ends with, or the generic
ones where it is refused). Rows, each a largest s (bisection, 2 % in s):

- ``design (45)-(46)``, ``design (45)-(46) or (29)``: what the tool certifies (:func:`~fte_casadi.design.diagnose.
  tolerance`, its decisions as the design makes them: step 3 at s, then step 5 at cond(Pbar) <= 1e4 with margins);
- at step 3's K (step 3 at the plant's diffusion), no bound on cond(Pbar), no margins, by Clarabel: ``(46) at X``
  (the paper's step 5: Theorem 2's split ``-sigma P^2`` and step 3's ``P = X^-1``), ``(29) at P = c X^-1`` (the
  split removed, P kept up to a scale), ``(29)`` (P free too: the common, block-diagonal ``V = x'P x + e'Pbar e``),
  ``mean-square stability, block-diagonal V`` ((29) without the attenuation gamma);
- at the gains (K, L_i1) of the design at the defaults: ``(29) at its gains``, ``one full V at its gains`` (a common
  ``[x; e]' P [x; e]``, not block-diagonal), ``each frozen rule, exactly`` (the spectral abscissa of the second
  moments' Lyapunov operator, no common V: the most any certificate of these gains can claim);
- ``no controller can (each rule)``: mean-square stabilisability and detectability
  (:func:`fte_casadi.design.diagnose.decide`).
"""

from __future__ import annotations

import math
import time

import numpy as np

from fte_casadi._text import shorten

__all__ = ["diffusion_scales"]

EPS = 1e-7


def _solve(cons) -> bool:
    """Feasible, by Clarabel: "optimal" only (an inaccurate answer counts as infeasible, so each row's scale errs
    low, and cvxpy's warning about it is not passed on to the command's output)."""
    import warnings

    import cvxpy as cp

    prob = cp.Problem(cp.Minimize(0), cons)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message="Solution may be inaccurate", category=UserWarning)
            prob.solve(solver="CLARABEL")
    except cp.SolverError:
        return False
    return prob.status == "optimal"


def _largest(feasible, top: float = 1e4) -> float:
    """The largest s in [0, top] with ``feasible(s)`` (monotone), by doubling then bisection to 2 %; 0: not at 1e-6."""
    lo, hi = 0.0, 1.0
    if feasible(hi):
        lo = hi
        while hi < top:
            hi *= 4.0
            if not feasible(hi):
                break
            lo = hi
        else:
            return math.inf
    else:
        while not feasible(hi / 4.0):
            hi /= 4.0
            if hi < 1e-6:
                return 0.0
        lo = hi / 4.0
    while hi > 1.02 * lo:
        mid = math.sqrt(lo * hi)
        lo, hi = (mid, hi) if feasible(mid) else (lo, mid)
    return lo


def _parts(aug, i):
    n, lf = aug.n, aug.lf
    return aug.Abar[i][:n, :n], aug.Bbar[i][:n], aug.Abar[i][:n, n + lf :], aug.Wbar[i][:n], aug.Bdbar[i][:n]


def _closed_loop(aug, T, K, L1, i):
    """(27) of rule i at the gains: ``d[x; e] = Acl [x; e] dt + Wcl [x; e] dw``."""
    n, nbar = aug.n, aug.nbar
    A, B, Bf, W, _ = _parts(aug, i)
    Be = B @ K @ aug.J0 - Bf @ aug.J2
    R = T @ aug.Abar[i] - L1[i] @ aug.Cbar
    Acl = np.block([[A + B @ K, -Be], [np.zeros((nbar, n)), R]])
    Wcl = np.block([[W, np.zeros((n, nbar))], [T @ aug.Wbar[i], np.zeros((nbar, nbar))]])
    return Acl, Wcl


def _exact(Acl, Wcl) -> float:
    """The largest s with ``(Acl, s Wcl)`` mean-square stable: ``1 / sqrt(rho(-L^-1 (Wcl x Wcl)))``, L the
    Lyapunov operator ``S -> Acl S + S Acl^T`` (Kronecker form)."""
    N = Acl.shape[0]
    if np.max(np.linalg.eigvals(Acl).real) >= 0:
        return 0.0
    L = np.kron(np.eye(N), Acl) + np.kron(Acl, np.eye(N))
    rho = max(abs(np.linalg.eigvals(-np.linalg.solve(L, np.kron(Wcl, Wcl)))))
    return 1.0 / math.sqrt(rho) if rho > 0 else math.inf


def _thm1(aug, T, K, s, gamma, *, P_fixed=None, perf=True, L_fixed=None) -> bool:
    """(29) at K (and at ``L_fixed``, ``c P_fixed`` when given), the diffusion scaled by s."""
    import cvxpy as cp

    n, nbar, ld, p = aug.n, aug.nbar, aug.ld, aug.p
    Cb = aug.Cbar
    C, De = Cb[:, :n], Cb[:, n + aug.lf :] @ aug.J2
    if P_fixed is None:
        P = cp.Variable((n, n), symmetric=True)
        cons = [P >> (EPS if perf else 1.0) * np.eye(n)]
    else:
        c = cp.Variable()
        P, cons = c * P_fixed, [c >= EPS]
    Pb = cp.Variable((nbar, nbar), symmetric=True)
    cons.append(Pb >> (EPS if perf else 1.0) * np.eye(nbar))
    for i in range(aug.r):
        A, B, Bf, W, Bd = _parts(aug, i)
        Be = B @ K @ aug.J0 - Bf @ aug.J2
        Acl, Wb, Ws = A + B @ K, s * T @ aug.Wbar[i], s * W
        QC = cp.Variable((nbar, p)) @ Cb if L_fixed is None else Pb @ L_fixed[i] @ Cb
        O11 = P @ Acl + Acl.T @ P + Ws.T @ P @ Ws + Wb.T @ Pb @ Wb
        O13 = -P @ Be
        O33 = Pb @ T @ aug.Abar[i] + aug.Abar[i].T @ T.T @ Pb - QC - QC.T
        if perf:
            O11, O13, O33 = O11 + C.T @ C, O13 + C.T @ De, O33 + De.T @ De
            M = cp.bmat([[O11, P @ Bd, O13], [(P @ Bd).T, -(gamma**2) * np.eye(ld), np.zeros((ld, nbar))],
                         [O13.T, np.zeros((nbar, ld)), O33]])  # fmt: skip
        else:
            M = cp.bmat([[O11, O13], [O13.T, O33]])
        cons.append(0.5 * (M + M.T) << -EPS * np.eye(M.shape[0]))
    return _solve(cons)


def _paper46(aug, T, K, X, s, params) -> bool:
    """(45) at step 3's (X, K) and (46) in (Pbar, Q_i), the diffusion scaled by s, without a bound on cond(Pbar)."""
    import cvxpy as cp

    from fte_casadi.design.core import lmi45, lmi46_terms
    from fte_casadi.design.diagnose import scaled

    a = scaled(aug, s)
    sg, g, g1 = params["sigma"], params["gamma"], params["gamma1"]
    if any(np.linalg.eigvalsh(lmi45(a, i, X, K @ X, sg, g, g1))[-1] >= 0 for i in range(aug.r)):
        return False
    P = np.linalg.inv(X)
    n, nbar, p = aug.n, aug.nbar, aug.p
    Pb = cp.Variable((nbar, nbar), symmetric=True)
    cons = [Pb >> EPS * np.eye(nbar)]
    for i in range(aug.r):
        t = lmi46_terms(a, i, K)
        Q = cp.Variable((nbar, p))
        Ab, Cb = a.Abar[i], a.Cbar
        T11 = -sg * P @ P + t["Wbk"].T @ T.T @ Pb @ T @ t["Wbk"]
        T13 = -P @ t["Be"] + t["C"].T @ t["De"]
        T33 = Pb @ T @ Ab + Ab.T @ T.T @ Pb - Q @ Cb - Cb.T @ Q.T + t["De"].T @ t["De"]
        M = cp.bmat([[T11, T13], [T13.T, T33]])
        cons.append(0.5 * (M + M.T) << -EPS * np.eye(n + nbar))
    return _solve(cons)


def _common_full(aug, T, K, L1, s) -> bool:
    """One full ``[x; e]' P [x; e]`` for every rule at the gains, the diffusion scaled by s (balanced coordinates)."""
    import cvxpy as cp
    from scipy.linalg import matrix_balance

    loops = [_closed_loop(aug, T, K, L1, i) for i in range(aug.r)]
    _, (sc, _) = matrix_balance(sum(np.abs(A) for A, _ in loops), permute=False, separate=True)
    D, Di = np.diag(sc), np.diag(1.0 / sc)
    N = aug.n + aug.nbar
    P = cp.Variable((N, N), symmetric=True)
    cons = [P >> np.eye(N)]
    for A, W in loops:
        A, W = Di @ A @ D, Di @ W @ D
        M = A.T @ P + P @ A + s**2 * W.T @ P @ W
        cons.append(0.5 * (M + M.T) << -EPS * np.eye(N))
    return _solve(cons)


def diffusion_scales(spec: str, params: dict | None = None, log=None) -> dict:
    """The rows of the module docstring for the plant ``spec`` (``FILE.py:FUNCTION`` or a built-in name); ``log``
    (default: nothing) is told each row as it is measured. A row that is not finite is given as its text (JSON)."""
    log = (lambda _msg: None) if log is None else log
    from fte_casadi.design import augment, design, uio_gain
    from fte_casadi.design.core import step3
    from fte_casadi.design.diagnose import decide, tolerance
    from fte_casadi.errors import FteError
    from fte_casadi.plants import load_plant, load_scenario
    from fte_casadi.ts import derive

    ts = derive(load_plant(spec))
    try:
        sc = load_scenario(spec)
    except FteError:
        sc = None
    aug = augment(ts.local_models, ts.C, ts.Df)
    _, T = uio_gain(aug)
    options = {} if sc is None else {"sample_time": sc.dt}
    t0 = time.perf_counter()
    try:
        d = design(ts, **options, **(params or {}))
    except FteError as exc:
        d = None
        log(f"design at the defaults refused: {shorten(exc, 300)}")
    log(f"design at the defaults: {'certified by ' + str(d.checks['certified_by']) if d else 'refused'} "
        f"({time.perf_counter() - t0:.1f} s)")  # fmt: skip
    p = d.params.to_dict() if d is not None else dict(params or {})
    for k, v in {"sigma": 1.0, "gamma": 1.0, "gamma1": 0.5, "delta": 1e-4, "epsilon": 1e-4}.items():
        p.setdefault(k, v)
    p = {
        k: v for k, v in p.items() if k in ("sigma", "gamma", "gamma1", "gamma2", "delta", "epsilon", "kappa")
    }
    rows: dict = {"params": p}

    def row(name, value):
        rows[name] = value
        log(f"{name:<48} {value:.4g}" if isinstance(value, float) else f"{name:<48} {value}")

    for name, routes in (("design (45)-(46)", ("46",)), ("design (45)-(46) or (29)", ("46", "29"))):
        tol = tolerance(aug, T, p, "CLARABEL", routes=routes, top=1e3, steps=10)
        row(name, 1e3 if tol is None else tol.feasible)
    s3 = step3(aug, p, "CLARABEL")
    K, X = s3.K, s3.X
    g = p["gamma"]
    row("(46) at step 3's X", _largest(lambda s: _paper46(aug, T, K, X, s, p)))
    row("(29) at P = c X^-1", _largest(lambda s: _thm1(aug, T, K, s, g, P_fixed=np.linalg.inv(X))))
    row("(29), P free", _largest(lambda s: _thm1(aug, T, K, s, g)))
    row("mean-square stability, block-diagonal V", _largest(lambda s: _thm1(aug, T, K, s, g, perf=False)))
    if d is not None:
        Kd, L1 = np.asarray(d.K[0]), [np.asarray(M) for M in d.L1]
        row("(29) at the design's gains", _largest(lambda s: _thm1(aug, T, Kd, s, g, L_fixed=L1)))
        row("one full V at the design's gains", _largest(lambda s: _common_full(aug, T, Kd, L1, s)))
        row("each frozen rule, exactly, at the design's gains",
            min(_exact(*_closed_loop(aug, T, Kd, L1, i)) for i in range(aug.r)))  # fmt: skip
    for kind in ("stabilisable", "detectable"):
        row(f"no controller can: mean-square {kind}",
            min(_largest(lambda s, i=i, k=kind: bool(decide(aug, i, k, s, "CLARABEL"))) for i in range(aug.r)))  # fmt: skip
    rows["seconds"] = time.perf_counter() - t0
    return {k: (v if not isinstance(v, float) or math.isfinite(v) else str(v)) for k, v in rows.items()}
