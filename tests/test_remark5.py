"""Remark 5 in use (issue #19 items 1 and 4): a plant whose unknown input H cannot decouple is designed
with the sliding term widened to ``[Bdbar_u J1]``, certified, simulated and exported to C; a plant whose
Bd_i depends on the rule is told so (and designed with Remark 5, which makes its assumptions hold)."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from certified import assert_certified
from plant_bd_rules import plant as bd_plant
from plant_bd_rules import scenario as bd_scenario
from plant_remark5 import plant, scenario
from tolerances import C_DOUBLE

from fte_casadi.codegen import CStep, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.design import Design, augment, design
from fte_casadi.design.core._certify import certificate
from fte_casadi.errors import AssumptionError, DesignFileError
from fte_casadi.sim import simulate
from fte_casadi.step import step_function
from fte_casadi.ts import derive

HERE = Path(__file__).resolve().parent
SAMPLE_TIME = 1e-3


@pytest.fixture(scope="module")
def ts5():
    return derive(plant())


@pytest.fixture(scope="module")
def r5(ts5):
    return design(ts5, sample_time=SAMPLE_TIME)


@pytest.fixture(scope="module")
def r5_bound(ts5):
    """The same plant with a true bound on |gust| (its scenario's amplitude) in the sliding gain."""
    return design(ts5, sample_time=SAMPLE_TIME, d_bound=0.5)


def _certified_beyond_roundoff(d: Design):
    assert d.certified
    for k, lam in d.checks["lmi_max_eig"].items():
        assert lam < -d.checks["lmi_roundoff"][k], (k, lam)


def test_without_the_fallback_assumption_1_is_refused(ts5):
    with pytest.raises(
        AssumptionError, match=r"assumption \(1\) fails.*Remark 5.*\"gust\".*accept-assumption 1"
    ):
        design(ts5, sample_time=SAMPLE_TIME, remark5=False)


def test_fallback_designs_and_certifies_with_the_widened_sliding_term(r5):
    d = r5
    _certified_beyond_roundoff(d)
    rk = d.remark5
    assert rk["used"] and rk["unknown_inputs"] == ["gust"] and rk["attenuated_directions"] == 1
    assert rk["decoupled_directions"] == 0 and np.max(np.abs(d.H)) == 0  # nothing H can decouple
    lf, nbar, p = d.dims.lf, d.nbar, d.dims.p
    Bdu = np.array(rk["Bdu"])
    assert d.Ls.shape == (nbar, lf + 1) and d.N.shape == (lf + 1, p)
    Cbar = np.hstack([d.C, np.zeros((p, lf)), d.Df])
    assert np.max(np.abs(Cbar @ Bdu)) < 1e-12  # the outputs do not see it: that is why (1) fails
    for i, lm in enumerate(d.local_models):  # T Bdbar_i = Bdu M_i: all of d that reaches the error
        Bdbar = np.vstack([lm.Bd, np.zeros((2 * lf, 1))])
        np.testing.assert_allclose(d.T @ Bdbar, Bdu @ np.array(rk["M"][i]), atol=1e-14)
    J1 = np.vstack([np.zeros((d.dims.n, lf)), np.eye(lf), np.zeros((lf, lf))])
    np.testing.assert_allclose(d.Ls, d.T @ np.hstack([Bdu, J1]), atol=1e-14)
    # the recorded certificate is the widened one: (55) rebuilt by hand with [Bdu J1] in place of J1
    E = np.hstack([Bdu, J1]).T @ d.T.T @ d.Pbar - d.N @ Cbar
    L55 = np.block([[-d.theta * np.eye(nbar), E.T], [E, -np.eye(lf + 1)]])
    assert np.max(np.linalg.eigvalsh(L55)) == pytest.approx(
        d.checks["lmi_raw_max_eig"]["55"], rel=1e-9, abs=1e-12
    )
    # and in the form certified, balanced by D = diag(|L_kk|^-1/2): [[-I, E^T/sqrt(theta)], [E/sqrt(theta), -I]]
    assert np.linalg.norm(E, 2) / np.sqrt(d.theta) - 1 == pytest.approx(
        d.checks["lmi_max_eig"]["55"], rel=1e-9
    )
    # ... and it differs from the unwidened one, so the widening is not a no-op
    aug = augment(d.local_models, d.C, d.Df)
    plain = certificate(aug, dict(X=d.X, K=d.K, P=d.P, T=d.T, Pbar=d.Pbar, Q=d.Q, N=d.N[1:], theta=d.theta,
                                  R=d.R, L1=d.L1), d.params.to_dict())  # fmt: skip
    assert plain["lmi_max_eig"]["55"] != pytest.approx(d.checks["lmi_max_eig"]["55"], rel=1e-6)
    assert any(s.startswith("Remark 5:") and '"gust"' in s for s in d.status)


def test_document_round_trip_and_old_documents(r5_bound, tmp_path):
    d = r5_bound
    np.testing.assert_allclose(d.sliding_gain(), [0.5 + 1e-4, 2e-4], rtol=1e-12)  # |M| = 1: gain 0.5 + eps
    d.save(tmp_path / "d.json")
    back = Design.load(tmp_path / "d.json")
    assert back.remark5 == d.to_dict()["remark5"] and np.array_equal(back.sliding_gain(), d.sliding_gain())
    doc = d.to_dict()
    del doc["remark5"]  # Ls wider than the faults with no remark5: refused, not silently misread
    with pytest.raises(DesignFileError, match="remark5"):
        Design.from_dict(doc)
    old = Design.load(HERE.parent / "generated" / "three_tank" / "design.json")  # written before remark5
    assert old.remark5 == {} and old.sliding_gain().shape == (old.dims.lf,)


def test_step_applies_each_sliding_gain(r5_bound):
    """z_next = z + Ts (sum_i h_i (...) + Ls diag(g) sgn(s)), rebuilt by hand from the step's own s."""
    d = r5_bound
    fn = step_function(d, SAMPLE_TIME)
    sched = d.scheduling_function()
    n, lf, m = d.dims.n, d.dims.lf, d.dims.m
    g = d.sliding_gain()
    assert g[0] > 100 * g[1]  # the gust's gain is the bound, the fault's delta + eps
    rng = np.random.default_rng(7)
    for _ in range(20):
        z, y = rng.normal(scale=0.5, size=d.nbar), rng.uniform(-1, 1, size=d.dims.p)
        zn, u, xb, _, s = (np.asarray(v).ravel() for v in fn(z, y))
        assert s.shape == (lf + 1,)
        h = np.asarray(sched(y, xb[:n])).ravel()
        rhs = d.Ls @ (g * np.sign(s))
        for i, lm in enumerate(d.local_models):
            TB = d.T @ np.vstack([lm.B, np.zeros((2 * lf, m))])
            rhs = rhs + h[i] * (d.R[i] @ z + TB @ u + (d.L1[i] + d.L2[i]) @ y)
        np.testing.assert_allclose(zn, z + SAMPLE_TIME * rhs, rtol=0, atol=1e-13)


@pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")
def test_c_equals_the_step_with_the_widened_sliding_term(r5_bound, tmp_path):
    d = r5_bound
    generate_c(d, tmp_path, sample_time=SAMPLE_TIME)
    header = (tmp_path / "fte_remark5.h").read_text()
    assert "#define FTE_REMARK5_NS 2" in header and "Remark 5" in header
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), d, "double")
    fn = step_function(d, SAMPLE_TIME)
    rng = np.random.default_rng(11)
    z = d.observer_start(np.zeros(d.dims.p))
    c.init(z)
    flips = 0
    for _ in range(50):
        y = rng.normal(scale=0.3, size=d.dims.p)
        zn, u, xb, yc, s = (np.asarray(v).ravel() for v in fn(z, y))
        rc, uc, xbc, ycc = c.step(y)
        assert rc == 0
        assert np.max(np.abs(c.z - zn)) <= C_DOUBLE and np.max(np.abs(uc - u)) <= C_DOUBLE
        flips += s[0] > 0
        z = zn
    assert 0 < flips < 50  # the gust's sliding variable took both signs: both branches compared


def test_monte_carlo_estimates_the_fault_with_the_gust_acting(r5):
    """The fault is estimated with the undecoupled gust acting; the bar is set by what the same design
    achieves without the gust and by the trivial estimate fhat = 0 (relative error 1)."""
    with_gust = simulate(r5, plant(), scenario(0.5), paths=4, seed=1, progress=False).metrics
    calm = simulate(r5, plant(), scenario(0.0), paths=4, seed=1, progress=False).metrics
    # after the estimator settles (each window minus its first 20 %): the gust's cost, not the start-up
    e, e0 = with_gust["fault_rel_rms_error_settled"][0], calm["fault_rel_rms_error_settled"][0]
    assert e0 < 0.05  # measured 0.020
    assert e < 0.2  # measured 0.133: the gust (amplitude 0.5, as large as the fault) costs some accuracy
    assert with_gust["ftc_true_ratio"] < 0.1  # measured 0.039


@pytest.mark.slow
def test_rule_dependent_bd_is_named_and_remark5_used():
    """Issue #19 item 4: Bd_i differs between rules; decoupling both directions leaves (4) failing with
    s = 0. The message names the input, rules and entry, offers no --accept-assumption 4 (it cannot
    succeed), and says that Remark 5 makes (3) and (4) hold; with it on, the design certifies."""
    ts = derive(bd_plant())
    with pytest.raises(AssumptionError) as info:
        design(ts, sample_time=SAMPLE_TIME, remark5=False)
    msg = str(info.value)
    assert "assumption (4) fails" in msg and "s = 0" in msg
    assert 'rule-dependent Bd_i: unknown input "tau"' in msg and "rules [1, 2]" in msg
    assert '"vel" from 0.3624 to 1' in msg  # cos(theta) over |theta| <= 1.2
    assert "--accept-assumption 4" not in msg and "Accepting (4) cannot succeed" in msg
    assert "Remark 5's attenuation, which makes (3) and (4) hold here" in msg
    d = design(ts, sample_time=SAMPLE_TIME)
    _certified_beyond_roundoff(d)
    assert (
        d.remark5["used"] and d.remark5["unknown_inputs"] == ["tau"] and "mean direction" in d.remark5["why"]
    )
    assert d.remark5["decoupled_directions"] == 1  # H still decouples tau's mean direction
    m = simulate(d, bd_plant(), bd_scenario(0.5), paths=4, seed=1, progress=False).metrics
    assert m["fault_rel_rms_error_settled"][0] < 0.4  # measured 0.28 (the whole window: 0.36)


def _cli(*args):
    return subprocess.run(
        [sys.executable, "-m", "fte_casadi", *args], capture_output=True, text=True, timeout=300
    )


@pytest.mark.slow
def test_cli_no_remark5_gives_the_refusal(tmp_path):
    spec = f"{HERE / 'plant_remark5.py'}:plant"
    off = _cli("design", spec, "--no-remark5", "--sample-time", "0.001")
    assert off.returncode != 0 and "Traceback" not in off.stderr
    assert "assumption (1) fails" in off.stderr + off.stdout and "Remark 5" in off.stderr + off.stdout
    on = _cli("design", spec, "--sample-time", "0.001", "--d-bound", "0.5", "-o", str(tmp_path / "d.json"))
    assert on.returncode == 0, on.stderr
    assert_certified(on.stdout, tmp_path / "d.json")
    assert "Remark 5: H cannot decouple every unknown input" in on.stdout
    assert Design.load(tmp_path / "d.json").remark5["d_bound"] == [0.5]
