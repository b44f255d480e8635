"""Tests of fte_casadi.design: H, assumption checks, LMI design, certificates, JSON round trip."""

from __future__ import annotations

import warnings

import casadi as ca
import numpy as np
import pytest

from fte_casadi.design import Design, augment, check_assumptions, design, enforce, invariant_zeros, uio_gain
from fte_casadi.design.certify import lmi45, lmi46, lmi55, lmi64
from fte_casadi.errors import AssumptionError, InfeasibleDesignError, ParameterError
from fte_casadi.model import PlantBuilder
from fte_casadi.plants import manipulator, three_tank
from fte_casadi.ts import derive

H_TOL = 1e-6
H_MANIP = np.array([
    [0.0714286, -0.1428571, 0.2142857], [-0.1428571, 0.2857143, -0.4285714],
    [0.2142857, -0.4285714, 0.6428571], [0.3571429, -0.7142857, 1.0714286],
] + [[0.0, 0.0, 0.0]] * 4)  # fmt: skip
H_TANK = np.array([[0.2, -0.4], [-0.4, 0.8], [1.0, -2.0], [0.0, 0.0], [0.0, 0.0]])

warnings.filterwarnings("ignore", message="Solution may be inaccurate")


@pytest.fixture(scope="module")
def ts_models():
    return {
        "manipulator": derive(manipulator(), fidelity_samples=500),
        "three-tank": derive(three_tank(), fidelity_samples=500),
    }


@pytest.fixture(scope="module")
def designs(ts_models):
    return {k: design(ts) for k, ts in ts_models.items()}


@pytest.mark.parametrize("name,H", [("manipulator", H_MANIP), ("three-tank", H_TANK)])
def test_H_equals_printed(ts_models, name, H):
    ts = ts_models[name]
    Hc, T = uio_gain(augment(ts.local_models, ts.C, ts.Df))
    assert np.max(np.abs(Hc - H)) < H_TOL
    aug = augment(ts.local_models, ts.C, ts.Df)
    for Bd in aug.Bdbar:  # (12): T Bdbar_i = 0
        assert np.max(np.abs(T @ Bd)) < 1e-12


@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_paper_examples_satisfy_assumptions(ts_models, name):
    ts = ts_models[name]
    aug = augment(ts.local_models, ts.C, ts.Df)
    checks = check_assumptions(aug, uio_gain(aug)[1])
    assert [c.name for c in checks] == ["(1)", "(2)", "(3)", "(4)", "(5)"]
    assert all(c.holds for c in checks)


def _lm(A, B, Bd, Bf, W=None):
    n = A.shape[0]
    return dict(A=A, B=B, Bd=Bd, Bf=Bf, W=np.zeros((n, n)) if W is None else W)


A2 = np.array([[0.0, 1.0], [-2.0, -3.0]])
E1, E2 = np.array([[1.0], [0.0]]), np.array([[0.0], [1.0]])


def _checks(lm, C, Df):
    aug = augment([lm], C, Df)
    return {c.name: c for c in check_assumptions(aug, uio_gain(aug)[1])}


def test_assumption_1_fails_when_output_blind_to_d():
    c = _checks(_lm(A2, E2, E2, E2), np.array([[1.0, 0.0]]), np.zeros((1, 1)))["(1)"]
    assert not c.holds and "Remark 5" in c.message and c.numbers == {"rank_CBd": 0, "rank_Bd": 1}


def test_assumption_2_fails_when_fault_and_d_coincide():
    c = _checks(_lm(A2, E2, E2, E2), np.eye(2), np.zeros((2, 1)))["(2)"]
    assert not c.holds and c.numbers["ranks"] == [3] and c.numbers["columns"] == 4


def test_assumption_3_names_right_half_plane_zero():
    C = np.array([[-0.41, 1.0]])  # (s - 0.41) / (s^2 + 3 s + 2)
    z = invariant_zeros(A2, E2, C)
    assert z is not None and np.allclose(z, [0.41])
    c = _checks(_lm(A2, E2, E2, E1), C, np.zeros((1, 1)))["(3)"]
    assert not c.holds and "invariant zero at s = 0.41 in the right half plane" in c.message


def test_assumption_4_names_unobservable_eigenvalue():
    A = np.array([[0.5, 0.0], [0.0, -1.0]])
    c = _checks(_lm(A, E1, np.zeros((2, 0)), E1), np.array([[0.0, 1.0]]), np.zeros((1, 1)))["(4)"]
    assert not c.holds and "0.5" in c.message


def test_assumption_5_fails_for_unmatched_actuator_fault():
    c = _checks(_lm(A2, E2, np.zeros((2, 0)), E1), np.eye(2), np.zeros((2, 1)))["(5)"]
    assert not c.holds


def test_enforce_raises_and_accepts():
    aug = augment([_lm(A2, E2, E2, E1)], np.array([[-0.41, 1.0]]), np.zeros((1, 1)))
    checks = check_assumptions(aug, uio_gain(aug)[1])
    with pytest.raises(AssumptionError, match=r"assumption \(3\) fails"):
        enforce(checks)
    notes = enforce(checks, accept=True)
    assert any("assumption (3) fails" in s for s in notes)
    with pytest.raises(AssumptionError) as exc:
        enforce(checks, accept=["3"])
    assert "assumption (3)" not in str(exc.value)


@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_conditioned_design_acceptance(designs, name):
    d = designs[name]
    c = d.checks
    assert d.certified and d.variant == "conditioned"
    assert np.max(np.abs(d.H - (H_MANIP if name == "manipulator" else H_TANK))) < H_TOL
    assert all(c["lmi_max_eig"][k] < 0 for k in ("45", "46", "55", "64"))
    assert c["R_max_real_eig"] < 0 and c["closed_loop_max_real_eig"] < 0
    assert c["cond_Pbar"] <= 1e5 and c["max_abs_L1"] <= 1e4
    assert c["ts_max"] > 0
    if name == "manipulator":
        assert c["max_abs_K"] <= 5
        assert c["ts_max"] >= 2e-3  # simulated at dt = 1e-3 s
        assert np.allclose(d.Kf, [[-1.0, 0.0]])


@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_certificate_recomputed_from_saved_json(designs, name, tmp_path):
    d = designs[name]
    path = tmp_path / "d.json"
    d.save(path)
    e = Design.load(path)
    assert e.to_dict() == d.to_dict()
    aug = augment(e.local_models, e.C, e.Df)
    pr = e.params
    worst = {"45": -np.inf, "46": -np.inf, "55": -np.inf, "64": -np.inf}
    for i in range(e.r):
        for j in range(e.r):
            worst["45"] = max(
                worst["45"],
                np.linalg.eigvalsh(lmi45(aug, i, e.X, e.K[j] @ e.X, pr["sigma"], pr["gamma"], pr["gamma1"]))[
                    -1
                ],
            )
            worst["46"] = max(
                worst["46"],
                np.linalg.eigvalsh(
                    lmi46(aug, i, e.K[j], e.P, e.T, e.Pbar, e.Q[i], pr["sigma"], pr["gamma1"])
                )[-1],
            )
        worst["64"] = max(worst["64"], np.linalg.eigvalsh(lmi64(aug, i, e.T, e.Pbar, e.theta))[-1])
        R = e.T @ aug.Abar[i] - np.linalg.solve(e.Pbar, e.Q[i]) @ aug.Cbar
        assert np.allclose(R, e.R[i], atol=1e-9 * max(1.0, np.abs(R).max()))
        assert np.max(np.linalg.eigvals(e.R[i]).real) < 0
    worst["55"] = np.linalg.eigvalsh(lmi55(aug, e.T, e.Pbar, e.N, e.theta))[-1]
    for k, v in worst.items():
        assert v < 0
        assert v == pytest.approx(e.checks["lmi_max_eig"][k], rel=1e-6, abs=1e-12)


def test_three_tank_reference_input(designs):
    d = designs["three-tank"]
    f = three_tank().drift_function()
    h = np.array(d.scheduling_function()(d.x_ref[:2], d.x_ref)).ravel()
    u = d.u_ref + sum(h[j] * d.K[j] for j in range(d.r)) @ d.x_ref
    assert np.max(np.abs(np.array(f(d.x_ref, u, 0, 0)))) < 1e-9


def test_infeasible_gamma_names_lmi(ts_models):
    with pytest.raises(InfeasibleDesignError, match=r"LMI \(45\) is infeasible: gamma = 1e-06 is below"):
        design(ts_models["manipulator"], gamma=1e-6)


@pytest.mark.parametrize("kw", [{"gamma": -1.0}, {"sigma": float("nan")}, {"gamma1": float("inf")},
                                {"gamma": 1.0, "gamma1": 1.0}, {"variant": "fancy"}, {"solver": "MOSEK9"}])  # fmt: skip
def test_bad_parameters(ts_models, kw):
    with pytest.raises(ParameterError):
        design(ts_models["manipulator"], **kw)


@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_paper_variant_never_claims_false_certificate(ts_models, name):
    try:
        d = design(ts_models[name], variant="paper", allow_uncertified=True)
    except InfeasibleDesignError as exc:
        assert "LMI (46)" in str(exc) or "LMI (45)" in str(exc)
        return
    c = d.checks
    holds = (
        all(v < 0 for v in c["lmi_max_eig"].values()) and c["R_max_real_eig"] < 0 and c["Pbar_min_eig"] > 0
    )
    assert d.certified == holds


def _diffusion_manipulator(beta_s=0.003, beta_sf=0.003):
    """The manipulator with G = beta_s B and Gf = beta_sf Bf (Theorem 5)."""
    b = PlantBuilder("manipulator-t5")
    th_m, w_m, th_l, w_l = b.states("theta_m", "w_m", "theta_l", "w_l")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    mu = b.premise("mu", ca.if_else(ca.fabs(th_l) < 1e-4, 1 - th_l**2 / 6, ca.sin(th_l) / th_l))
    b.drift([w_m + 0.1 * d, 48.6 * (th_l - th_m) - 1.25 * w_m + 21.6 * (u + fa) - 0.2 * d, w_l + 0.3 * d,
             -19.5 * (th_l - th_m) - 3.33 * mu * th_l + 0.5 * d])  # fmt: skip
    b.diffusion(
        [
            0.0006 * w_m,
            0.001 * th_l + 21.6 * (beta_s * u + beta_sf * fa),
            0.0005 * w_l,
            0.006 * th_l + 0.003 * mu * th_l,
        ]
    )
    b.outputs([th_m + fs, w_m, th_l])
    b.region(
        theta_l=(-2 * ca.pi, 2 * ca.pi), theta_m=(-2 * ca.pi, 2 * ca.pi), w_m=(-5.0, 5.0), w_l=(-5.0, 5.0)
    )
    b.reference(u=[2.0])
    b.design_defaults(gamma=2.0, gamma1=0.01, sigma=0.2, delta=1e-5, epsilon=1e-5)
    return b.build()


def test_theorem5_with_diffusion_in_u_and_f():
    ts = derive(_diffusion_manipulator(), fidelity_samples=200)
    assert ts.local_models[0].has_diffusion_extension
    assert np.allclose(ts.local_models[0].G, 0.003 * ts.local_models[0].B)
    d = design(ts)
    c = d.checks
    assert c["theorem"] == 5 and d.certified
    assert all(c["lmi_max_eig"][k] < 0 for k in ("78", "79", "80", "81"))
    assert c["lmi_max_eig"]["79"] == c["lmi_max_eig"]["46"]
    aug = augment(d.local_models, d.C, d.Df)
    pr = d.params
    for i in range(d.r):
        for j in range(d.r):  # (79) with its G terms, recomputed; differs from (46) without them
            L = lmi46(aug, i, d.K[j], d.P, d.T, d.Pbar, d.Q[i], pr["sigma"], pr["gamma1"])
            assert np.linalg.eigvalsh(L)[-1] < 0
    no_g = augment(
        [{k: v for k, v in lm.items() if k not in ("G", "Gf")} for lm in d.local_models], d.C, d.Df
    )
    L0 = lmi46(no_g, 0, d.K[0], d.P, d.T, d.Pbar, d.Q[0], pr["sigma"], pr["gamma1"])
    L5 = lmi46(aug, 0, d.K[0], d.P, d.T, d.Pbar, d.Q[0], pr["sigma"], pr["gamma1"])
    assert np.max(np.abs(L5 - L0)) > 1e-8  # the G, Gf terms of (79) are really there


def test_three_tank_observer_decays_within_the_fault_window(designs):
    """The three-tank observer must settle well inside the 200 s fault window, with gains that
    the simulation at dt = 0.01 s can run (ts_max) and a controller gain below the printed ~2206."""
    c = designs["three-tank"].checks
    assert c["R_max_real_eig"] <= -0.01
    assert c["ts_max"] >= 0.02
    assert c["max_abs_K"] <= 2206
    assert c["cond_Pbar"] <= 1e5 and c["max_abs_L1"] <= 1e4


def test_no_solver_warning_leaks_and_status_records_it(ts_models):
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        d = design(ts_models["manipulator"])
    assert not [w for w in caught if "inaccurate" in str(w.message)]
    assert d.certified
    assert any("warned" in s for s in d.status) == any("inaccurate" in s for s in d.status)


def test_step5_acceptance_uses_the_numpy_certificate(designs):
    """A point is accepted only if its recomputed LMIs hold: a perturbed Q_i is rejected."""
    from fte_casadi.design.lmi import _check5

    d = designs["manipulator"]
    aug = augment(d.local_models, d.C, d.Df)
    point = (d.Pbar, list(d.Q), d.N, d.theta)
    assert _check5(aug, d.params, d.P, list(d.K), d.T, point, 0.0)[0]
    bad = (d.Pbar, [-Q for Q in d.Q], d.N, d.theta)
    holds, why = _check5(aug, d.params, d.P, list(d.K), d.T, bad, 0.0)
    assert not holds and "(46)" in why


def test_scs_certifies_or_fails_fast(ts_models):
    import time

    t0 = time.perf_counter()
    try:
        d = design(ts_models["manipulator"], solver="SCS")
    except InfeasibleDesignError as exc:
        assert "SCS" in str(exc)
    else:
        assert d.certified
    assert time.perf_counter() - t0 < 45
