"""Shared fixtures: built-in plants, their T-S models and designs.

``lqr_design`` builds a Design record *without* the LMI machinery (H and T by docs/method.md's
(17)-(18), K_j and L1_i by LQR, N = 0) so that simulation and plotting can be tested on a
stable closed loop independently of the design code; ``real_designs`` are the conditioned
LMI designs, made once per session.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import scipy.linalg as sla

# compiled closed loops go to a cache shared by the test session (not the user's home)
os.environ.setdefault(
    "FTE_CACHE_DIR", os.path.join(os.environ.get("TMPDIR", "/tmp"), "fte_casadi_test_cache")
)
# the detection thresholds' calibration within a small budget of path-steps (the default, 2e7 per pass, is for
# a run's own promise; the tests of the promise ask for their paths explicitly: tests/test_detection_promise.py)
os.environ.setdefault("FTE_CALIBRATION_BUDGET", "2e5")

import matplotlib  # noqa: E402
from hypothesis import settings  # noqa: E402

matplotlib.use("Agg")
# property tests draw the same examples on every run (a CI run neither fails nor slows down by the luck of the draw);
# HYPOTHESIS_PROFILE=explore draws new ones each run, to look for failures on purpose
settings.register_profile("fte", derandomize=True)
settings.register_profile("explore", derandomize=False)
settings.load_profile(os.environ.get("HYPOTHESIS_PROFILE", "fte"))

from fte_casadi.design import Design, design  # noqa: E402
from fte_casadi.plants import manipulator, three_tank  # noqa: E402
from fte_casadi.ts import derive, scheduling_from_measurements  # noqa: E402


def _lqr(A, B, Q, R):
    P = sla.solve_continuous_are(A, B, Q, R)
    return -np.linalg.solve(R, B.T @ P)


def _ts_max(R_list) -> float:
    """Largest Ts with every I + Ts R_i Schur stable (bisection on the spectral radius)."""
    lo, hi = 0.0, 10.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        ok = all(np.max(np.abs(np.linalg.eigvals(np.eye(len(R)) + mid * R))) < 1 for R in R_list)
        lo, hi = (mid, hi) if ok else (lo, mid)
    return lo


def lqr_design(ts, *, q_state=1.0, q_fault=1e3, r_obs=1e-2) -> Design:
    """A stable, not LMI-certified Design record for the T-S model ``ts`` (tests only)."""
    plant = ts.plant
    n, m, p, lf, ld, r = ts.n, ts.m, ts.p, ts.lf, ts.ld, ts.r
    nbar = n + 2 * lf
    lms = ts.local_models
    C, Df = ts.C, ts.Df
    Cbar = np.hstack([C, np.zeros((p, lf)), Df])
    Abar = [
        np.block(
            [
                [lm.A, np.zeros((n, lf)), lm.Bf],
                [np.zeros((lf, nbar))],
                [np.zeros((lf, n)), np.eye(lf), np.zeros((lf, lf))],
            ]
        )
        for lm in lms
    ]
    Bdbar = np.hstack([np.vstack([lm.Bd, np.zeros((2 * lf, ld))]) for lm in lms])
    U, sv, _ = np.linalg.svd(Bdbar)
    BU = U[:, : int(np.sum(sv > 1e-9 * max(sv.max(), 1)))] if Bdbar.size else np.zeros((nbar, 0))
    CB = Cbar @ BU
    H = BU @ np.linalg.solve(CB.T @ CB, CB.T) if BU.shape[1] else np.zeros((nbar, p))
    T = np.eye(nbar) - H @ Cbar
    Aavg = sum(lm.A for lm in lms) / r
    B = lms[0].B
    K = _lqr(Aavg, B, q_state * np.eye(n), np.eye(m))
    Kf = -np.linalg.pinv(B) @ lms[0].Bf
    Qo = np.diag([q_state] * n + [q_fault] * (2 * lf))
    L1, R, L2 = [], [], []
    for Ab in Abar:
        L = _lqr((T @ Ab).T, Cbar.T, Qo, r_obs * np.eye(p)).T * -1.0
        L1.append(L)
        Ri = T @ Ab - L @ Cbar
        R.append(Ri)
        L2.append(Ri @ H)
    if plant.u_ref is not None:
        u_ref = np.asarray(plant.u_ref, float)
    else:
        u_eq = np.asarray(plant.operating_inputs[len(plant.operating_inputs) // 2], float)
        u_ref = u_eq - K @ np.asarray(plant.x_ref, float)
    sched, _ = scheduling_from_measurements(ts)
    Acl = [lm.A + lm.B @ K for lm in lms]
    J1 = np.vstack([np.zeros((n, lf)), np.eye(lf), np.zeros((lf, lf))])
    eye = np.eye(nbar)
    return Design(
        plant=plant.name,
        plant_spec=plant.name,
        variant="test-lqr",
        solver="scipy-lqr",
        params=dict(plant.design_defaults),
        dims={"n": n, "m": m, "p": p, "ld": ld, "lf": lf, "r": r, "nbar": nbar},
        premises=[pr.to_dict() for pr in ts.premises],
        local_models=tuple(lms),
        C=C,
        Df=Df,
        H=H,
        T=T,
        X=np.eye(n),
        P=np.eye(n),
        K=tuple(K for _ in range(r)),
        Kf=Kf,
        Pbar=eye,
        Q=tuple(L1),
        N=np.zeros((lf, p)),
        theta=0.0,
        L1=tuple(L1),
        L2=tuple(L2),
        R=tuple(R),
        Ls=T @ J1,
        checks={
            "lmi_max_eig": {},
            "R_max_real_eig": max(np.linalg.eigvals(Ri).real.max() for Ri in R),
            "closed_loop_max_real_eig": max(np.linalg.eigvals(A).real.max() for A in Acl),
            "cond_Pbar": 1.0,
            "max_abs_L1": max(np.abs(L).max() for L in L1),
            "ts_max": _ts_max(R),
        },
        timings={"total_s": 0.0, "solver_s": 0.0},
        u_ref=u_ref,
        scheduling=sched.serialize(),
        names={"states": list(plant.state_names), "state_units": list(plant.state_units)},
        certified=False,
        status=["test fixture: LQR gains, no LMI certificate"],
        x_ref=None if plant.x_ref is None else np.asarray(plant.x_ref, float),
    )


@pytest.fixture(scope="session")
def plants():
    return {"manipulator": manipulator(), "three-tank": three_tank()}


@pytest.fixture(scope="session")
def ts_models(plants):
    return {k: derive(p, fidelity_samples=500) for k, p in plants.items()}


@pytest.fixture(scope="session")
def lqr_designs(ts_models):
    return {k: lqr_design(ts) for k, ts in ts_models.items()}


@pytest.fixture(scope="session")
def real_designs(ts_models):
    """The LMI designs (conditioned variant) of the built-in plants, made once per session."""
    from fte_casadi.plants import SCENARIOS

    return {
        k: design(ts, variant="conditioned", sample_time=SCENARIOS[k]().dt, initial_state=SCENARIOS[k]().x0)
        for k, ts in ts_models.items()
    }
