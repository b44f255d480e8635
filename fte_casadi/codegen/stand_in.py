"""An LQR stand-in design, used to exercise the C generator without the LMI design.

It fills every field of :class:`~fte_casadi.design.record.Design` from a derived T-S model
with SPEC.md's formulas for H (17)-(18) and T (14), state-feedback gains K_j by LQR on
(A_j, B_j), observer gains L_i1 by LQR on the dual of (T Abar_i, Cbar), then R_i (13),
L_i2 (15), Ls = T J1, N = 0.1 ones(lf, p), Kf = -pinv(B) Bf. It is *not* certified
(``certified=False``, ``variant="lqr-stand-in"``): each rule is stable on its own, no common
Lyapunov function is sought. The C generator only needs a record with the right fields, so
the generated code and its tests do not depend on the LMI solver.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from ..design.record import Design

__all__ = ["stand_in_design", "observer_ts_max"]


def _lqr(A: np.ndarray, B: np.ndarray, q: float = 1.0, r: float = 1.0) -> np.ndarray:
    """Gain K with A + B K Hurwitz (u = K x convention of SPEC.md)."""
    P = sla.solve_continuous_are(A, B, q * np.eye(A.shape[0]), r * np.eye(B.shape[1]))
    return -np.linalg.solve(r * np.eye(B.shape[1]), B.T @ P)


def observer_ts_max(R) -> float:
    """Largest Ts with every vertex ``I + Ts R_i`` a contraction in spectral radius.

    For an eigenvalue ``lam`` of ``R_i`` with ``Re lam < 0``, ``|1 + Ts lam| < 1`` holds for
    ``Ts < -2 Re(lam) / |lam|^2``; the minimum over all rules and eigenvalues is returned
    (``0.0`` when some R_i is not Hurwitz).
    """
    best = np.inf
    for Ri in R:
        lam = np.linalg.eigvals(np.asarray(Ri, dtype=float))
        if np.any(lam.real >= 0):
            return 0.0
        best = min(best, float(np.min(-2.0 * lam.real / np.abs(lam) ** 2)))
    return best


def _h_matrix(Bdbar_all: np.ndarray, Cbar: np.ndarray) -> np.ndarray:
    """(17)-(18): column-compress [Bdbar_1 ... Bdbar_r] to B_U, then the left inverse through Cbar."""
    U, sv, _ = np.linalg.svd(Bdbar_all, full_matrices=False)
    rank = int(np.sum(sv > 1e-10 * max(1.0, sv[0] if sv.size else 1.0)))
    BU = U[:, :rank] * sv[:rank]
    CB = Cbar @ BU
    return BU @ np.linalg.solve(CB.T @ CB, CB.T)


def stand_in_design(ts_model) -> Design:
    """Build an LQR-based (uncertified) :class:`Design` for a derived T-S model.

    Examples
    --------
    >>> from fte_casadi.plants import manipulator
    >>> from fte_casadi.ts import derive
    >>> d = stand_in_design(derive(manipulator(), fidelity_samples=200))
    >>> d.dims["nbar"], d.certified
    (8, False)
    """
    from ..ts import scheduling_from_measurements

    plant = ts_model.plant
    n, m, p, ld, lf, r = ts_model.n, ts_model.m, ts_model.p, ts_model.ld, ts_model.lf, ts_model.r
    nbar = n + 2 * lf
    C, Df = np.asarray(ts_model.C, float), np.asarray(ts_model.Df, float)
    Cbar = np.hstack([C, np.zeros((p, lf)), Df])
    J1 = np.vstack([np.zeros((n, lf)), np.eye(lf), np.zeros((lf, lf))])
    lms = ts_model.local_models

    def abar(lm):
        A = np.zeros((nbar, nbar))
        A[:n, :n] = lm.A
        A[:n, n + lf :] = lm.Bf
        A[n + lf :, n : n + lf] = np.eye(lf)
        return A

    Bdbar_all = np.hstack([np.vstack([lm.Bd, np.zeros((2 * lf, ld))]) for lm in lms])
    H = _h_matrix(Bdbar_all, Cbar)
    T = np.eye(nbar) - H @ Cbar
    K = tuple(_lqr(lm.A, lm.B) for lm in lms)
    L1, R, L2 = [], [], []
    for lm in lms:
        TA = T @ abar(lm)
        L = _lqr(TA.T, Cbar.T, q=1.0, r=1.0).T  # A^T + C^T L^T Hurwitz -> TA + L Cbar Hurwitz
        L1.append(-L)
        R.append(TA + L @ Cbar)
        L2.append(R[-1] @ H)
    B0, Bf0 = lms[0].B, lms[0].Bf
    Kf = -np.linalg.pinv(B0) @ Bf0
    if plant.u_ref is not None:
        u_ref = np.asarray(plant.u_ref, float)
    else:  # u_ref = u_eq - K(x_ref) x_ref, with the drift affine in u
        xr = np.asarray(plant.x_ref, float)
        F = plant.drift_function()
        f0 = np.asarray(F(xr, np.zeros(m), np.zeros(ld), np.zeros(lf))).ravel()
        Bu = np.column_stack(
            [np.asarray(F(xr, np.eye(m)[k], np.zeros(ld), np.zeros(lf))).ravel() - f0 for k in range(m)]
        )
        u_eq = -np.linalg.lstsq(Bu, f0, rcond=None)[0]
        h = ts_model.memberships(xr)
        u_ref = u_eq - sum(h[j] * K[j] for j in range(r)) @ xr
    sched = scheduling_from_measurements(ts_model)[0].serialize()
    A_cl = [lm.A + lm.B @ K[j] for j, lm in enumerate(lms)]
    checks = {
        "lmi_max_eig": {"45": 0.0, "46": 0.0, "55": 0.0, "64": 0.0},
        "R_max_real_eig": float(max(np.max(np.linalg.eigvals(Ri).real) for Ri in R)),
        "closed_loop_max_real_eig": float(max(np.max(np.linalg.eigvals(Ai).real) for Ai in A_cl)),
        "cond_Pbar": 1.0,
        "max_abs_L1": float(max(np.max(np.abs(Li)) for Li in L1)),
        "ts_max": observer_ts_max(R),
    }
    defaults = dict(plant.design_defaults)
    params = {k: float(defaults.get(k, 1e-4)) for k in ("gamma", "gamma1", "sigma", "delta", "epsilon")}
    return Design(
        plant=plant.name,
        plant_spec=plant.name,
        variant="lqr-stand-in",
        solver="scipy-care",
        params=params,
        dims={"n": n, "m": m, "p": p, "ld": ld, "lf": lf, "r": r, "nbar": nbar},
        premises=[pr.to_dict() for pr in ts_model.premises],
        local_models=tuple(
            {k: np.asarray(getattr(lm, k), float) for k in ("A", "B", "Bd", "Bf", "W", "a", "G", "Gf", "M")}
            for lm in lms
        ),
        C=C,
        Df=Df,
        H=H,
        T=T,
        X=np.eye(n),
        P=np.eye(n),
        K=K,
        Kf=Kf,
        Pbar=np.eye(nbar),
        Q=tuple(np.zeros((nbar, p)) for _ in range(r)),
        N=np.full((lf, p), 0.1),
        theta=0.0,
        L1=tuple(L1),
        L2=tuple(L2),
        R=tuple(R),
        Ls=T @ J1,
        checks=checks,
        timings={"total_s": 0.0, "solver_s": 0.0},
        u_ref=u_ref,
        scheduling=sched,
        names={
            "states": list(plant.state_names),
            "inputs": list(plant.input_names),
            "outputs": list(plant.output_names),
            "faults": list(plant.fault_names),
        },
        certified=False,
        status=["LQR stand-in for tests of the C generator; not an LMI design, not certified"],
        x_ref=None if plant.x_ref is None else np.asarray(plant.x_ref, float),
    )
