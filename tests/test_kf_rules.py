"""Issue #19 item 3: where -pinv(B_i) Bf_i differs between rules, the step blends Kf(h) = sum_i h_i Kf_i,
and the simulation and the C follow (one step Function for both)."""

from __future__ import annotations

import numpy as np
import pytest
from plant_kf_rules import plant, scenario
from tolerances import C_DOUBLE

from fte_casadi.codegen import CStep, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.design import Design, design
from fte_casadi.sim import simulate
from fte_casadi.step import step_function
from fte_casadi.ts import derive


@pytest.fixture(scope="module")
def kf_design():
    return design(derive(plant()), sigma=0.5, sample_time=scenario().dt)


def test_rules_keep_their_own_kf(kf_design, tmp_path):
    d = kf_design
    assert d.certified and d.Kf_rules is not None and len(d.Kf_rules) == d.r == 2
    B = [lm.B for lm in d.local_models]
    Bf = [lm.Bf for lm in d.local_models]
    for i in range(d.r):
        np.testing.assert_allclose(d.Kf_rules[i], -np.linalg.pinv(B[i]) @ Bf[i], rtol=1e-14)
    assert abs(float(d.Kf_rules[0][0, 0] - d.Kf_rules[1][0, 0])) > 0.05  # 1/(2 + cos x1) over [-1, 1]
    np.testing.assert_array_equal(d.Kf, d.Kf_rules[0])
    d.save(tmp_path / "d.json")
    back = Design.load(tmp_path / "d.json")
    for a, b in zip(back.Kf_rules, d.Kf_rules):
        np.testing.assert_array_equal(a, b)
    assert not any(s.startswith("warning: -pinv") for s in d.status)


def test_step_blends_kf_with_the_memberships(kf_design):
    d = kf_design
    fn = step_function(d, scenario().dt)
    sched = d.scheduling_function()
    rng = np.random.default_rng(3)
    n, lf = d.dims.n, d.dims.lf
    for _ in range(20):
        z, y = rng.normal(scale=0.5, size=d.nbar), rng.uniform(-0.9, 0.9, size=d.dims.p)
        _, u, xb, *_ = (np.asarray(v).ravel() for v in fn(z, y))
        xhat, fhat = xb[:n], xb[n + lf :]
        h = np.asarray(sched(y, xhat)).ravel()
        want = np.asarray(d.u_ref, float) + sum(
            h[i] * (np.asarray(d.K[i]) @ xhat + np.asarray(d.Kf_rules[i]) @ fhat) for i in range(d.r)
        )
        np.testing.assert_allclose(u, want, rtol=0, atol=1e-12)
        assert (
            0 < h[0] < 1 or abs(y[0]) < 1e-3
        )  # inside the region both rules take part (h = 1 only at x1 = 0)


@pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")
def test_c_and_simulation_run_the_scheduled_term(kf_design, tmp_path):
    d = kf_design
    sample_time = scenario().dt
    generate_c(d, tmp_path, sample_time=sample_time)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), d, "double")
    fn = step_function(d, sample_time)
    rng = np.random.default_rng(5)
    z = d.observer_start(np.zeros(d.dims.p))
    c.init(z)
    for _ in range(50):
        y = rng.normal(scale=0.3, size=d.dims.p)
        zn, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z, y))
        rc, uc, xbc, ycc = c.step(y)
        assert rc == 0
        assert np.max(np.abs(uc - u)) <= C_DOUBLE and np.max(np.abs(c.z - zn)) <= C_DOUBLE
        z = zn
    m = simulate(d, plant(), scenario(), paths=4, seed=1, progress=False).metrics
    assert m["fault_rel_rms_error"][0] < 0.3 and m["ftc_true_ratio"] < 0.5


@pytest.mark.slow
def test_parameters_the_user_did_not_set_are_found_by_the_tool(tmp_path):
    """Issue #17 item 2: the generic sigma fails on this plant; the tool picks one below the largest
    sigma (45) allows, certifies, and records what it chose and why. A sigma the user gave is kept."""
    ts = derive(plant())
    d = design(ts, sample_time=scenario().dt)
    assert d.certified and set(d.params_chosen) == {"sigma"}
    c = d.params_chosen["sigma"]
    assert c["value"] == d.params.sigma < 1.0 and "largest sigma for which (45) is feasible" in c["why"]
    d.save(tmp_path / "d.json")
    assert Design.load(tmp_path / "d.json").params_chosen == d.params_chosen
    with pytest.raises(Exception, match=r"LMI \(45\) is infeasible.*[Ll]ower sigma to <="):
        design(ts, sigma=1.0, sample_time=scenario().dt)
