"""Automatic sector nonlinearity and linear plants (issue #10)."""

from __future__ import annotations

import warnings

import casadi as ca
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from tolerances import C_DOUBLE, ROUNDOFF

from fte_casadi import PlantBuilder
from fte_casadi.codegen import build, generate_c
from fte_casadi.codegen.ctypes_step import CStep, closed_loop_compare
from fte_casadi.design import design
from fte_casadi.errors import DerivationError, PlantError
from fte_casadi.plants.manipulator import ALPHA_D, PARAMS, W
from fte_casadi.ts import derive
from fte_casadi.ts.fidelity import blended


def manipulator_plain():
    """The manipulator exactly as (82) prints it: plain sin(theta_l), no premise."""
    p, a, w = PARAMS, ALPHA_D, W
    b = PlantBuilder("manipulator-plain")
    th_m, w_m, th_l, w_l = b.states("theta_m", "w_m", "theta_l", "w_l")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([w_m + a[0] * d, p["k_Jm"] * (th_l - th_m) - p["G_Jm"] * w_m + p["ktau_Jm"] * (u + fa) + a[1] * d,
             w_l + a[2] * d, -p["k_Jl"] * (th_l - th_m) - p["mgh_Jl"] * ca.sin(th_l) + a[3] * d])  # fmt: skip
    b.diffusion([w["W12"] * w_m, w["W23"] * th_l + w["W21"] * th_m + w["W22"] * w_m, w["W34"] * w_l,
                 w["W43"] * th_l + w["W41"] * th_m + w["Ws"] * ca.sin(th_l)])  # fmt: skip
    b.outputs([th_m + fs, w_m, th_l])
    b.region(
        theta_l=(-2 * ca.pi, 2 * ca.pi), theta_m=(-2 * ca.pi, 2 * ca.pi), w_m=(-5.0, 5.0), w_l=(-5.0, 5.0)
    )
    b.reference(u=[2.0])
    b.initial_state([0.1, 0.05, 0.02, 0.03])
    b.design_defaults(gamma=2.0, gamma1=0.01, sigma=0.2, delta=1e-5, epsilon=1e-5)
    return b.build()


def linear_plant():
    b = PlantBuilder("linear")
    x1, x2, x3 = b.states("x1", "x2", "x3")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([x2 + 0.2 * d, -2 * x1 - x2 + x3 + u + fa, -x3 + 0.5 * x1 - 0.3 * d])
    b.diffusion([0.01 * x1, 0.0, 0.01 * x3])
    b.outputs([x1 + fs, x2, x3])
    b.reference(u=[0.5])
    b.initial_state([0.1, 0.0, 0.0])
    b.design_defaults(gamma=2.0, gamma1=0.1, sigma=0.2, delta=1e-4, epsilon=1e-4)
    return b.build()


def _two_state(drift_rows, diff_rows=(0.0, 0.0), region=((-2.0, 2.0), (-2.0, 2.0)), name="p"):
    b = PlantBuilder(name)
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    b.drift(drift_rows(x1, x2, u, fa))
    b.diffusion([r(x1, x2) if callable(r) else r for r in diff_rows])
    b.outputs([x1, x2])
    b.region(x1=region[0], x2=region[1])
    return b.build()


@pytest.fixture(scope="module")
def plain_and_builtin(ts_models):
    return derive(manipulator_plain()), ts_models["manipulator"]


def test_plain_manipulator_gives_the_paper_model(plain_and_builtin):
    ts, ref = plain_and_builtin
    assert ts.r == 2 and len(ts.premises) == 1 and "automatically" in ts.method
    pr = ts.premises[0]
    assert pr.expr == "(sin(theta_l)/theta_l)"
    assert pr.min == pytest.approx(-0.2172336, abs=1e-6) and pr.max == pytest.approx(1.0, abs=1e-12)
    for a, b in zip(ts.local_models, ref.local_models):  # same rule order as the built-in plant
        for k in ("A", "B", "Bd", "Bf", "W"):
            np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=0, atol=1e-12)
    assert ts.local_models[0].A[3, 2] == pytest.approx(-22.83, abs=1e-2)
    assert ts.fidelity.max_abs_error <= ROUNDOFF and ts.fidelity.trajectory_max_abs_error <= ROUNDOFF


def test_plain_manipulator_designs_simulates_and_generates_like_the_builtin(
    plain_and_builtin, real_designs, tmp_path
):
    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim import simulate

    ts, _ = plain_and_builtin
    d = design(ts, sample_time=1e-3)
    ref = real_designs["manipulator"]
    assert d.certified
    for a, b in zip(d.K + d.L1 + (d.N,), ref.K + ref.L1 + (ref.N,)):  # the design is a function of the model
        assert np.max(np.abs(a - b)) <= 1e-6 * np.max(np.abs(b))
    import dataclasses

    sc = dataclasses.replace(SCENARIOS["manipulator"](), T=4.0)
    m = simulate(d, ts.plant, sc, paths=4, seed=1, progress=False).metrics
    assert m["fault_rel_rms_error"][0] < 0.3
    if build.find_compiler() is not None:
        generate_c(d, tmp_path, ts=1e-3)
        lib = build.compile_shared(tmp_path, tmp_path / "lib.so")
        err, _ = closed_loop_compare(d, CStep(lib, d), 1e-3, 500, plant=ts.plant)
        assert max(err.values()) <= C_DOUBLE * 10


def test_bilinear_and_saturation_derive_with_four_rules():
    ts = derive(_two_state(lambda x1, x2, u, fa: [x2, -x1 * x2 - 2 * ca.tanh(x1) - 0.5 * x2 + u + fa],
                           diff_rows=(lambda x1, x2: 0.01 * x1, 0.0)))  # fmt: skip
    assert ts.r <= 4
    assert sorted(p.expr for p in ts.premises) == ["(tanh(x1)/x1)", "x1"]
    assert ts.fidelity.max_abs_error <= ROUNDOFF
    bounds = {p.expr: (p.min, p.max) for p in ts.premises}
    assert bounds["x1"] == pytest.approx((-2.0, 2.0), abs=1e-9)
    assert bounds["(tanh(x1)/x1)"] == pytest.approx((np.tanh(2.0) / 2.0, 1.0), abs=1e-6)


def test_unbounded_term_is_refused_by_name():
    with pytest.raises(DerivationError, match=r"drift row 'x2': the term \(-1/x1\) is not finite at x = 0"):
        derive(_two_state(lambda x1, x2, u, fa: [x2, -1 / x1 + u + fa], region=((-1.0, 1.0), (-1.0, 1.0))))


def test_input_entering_nonlinearly_is_refused_by_name():
    with pytest.raises(PlantError, match=r"drift row 'x2' is nonlinear in 'u'"):
        _two_state(lambda x1, x2, u, fa: [x2, ca.sin(u) + fa])


def test_state_dependent_input_gain_becomes_a_premise():
    ts = derive(_two_state(lambda x1, x2, u, fa: [x2, -x1 + (1 + 0.5 * ca.cos(x1)) * (u + fa)]))
    assert len(ts.premises) == 1 and "cos(x1)" in ts.premises[0].expr  # the input's coefficient itself
    Bs = sorted(float(lm.B[1, 0]) for lm in ts.local_models)
    assert Bs == pytest.approx([1 + 0.5 * np.cos(2.0), 1.5], abs=1e-9)
    assert ts.fidelity.max_abs_error <= ROUNDOFF


def test_linear_plant_is_one_rule_with_a_certified_design_and_working_c(tmp_path):
    ts = derive(linear_plant())
    assert ts.r == 1 and ts.premises == () and ts.method == "linear (one rule)"
    assert ts.fidelity.max_abs_error == 0.0
    np.testing.assert_array_equal(ts.memberships(np.zeros(3)), [1.0])
    d = design(ts, sample_time=1e-3)
    assert d.certified and all(v < 0 for v in d.checks["lmi_max_eig"].values())
    if build.find_compiler() is not None:
        generate_c(d, tmp_path, ts=1e-3)
        lib = build.compile_shared(tmp_path, tmp_path / "lib.so")
        err, traj = closed_loop_compare(d, CStep(lib, d), 1e-3, 800, plant=ts.plant,
                                        fault=lambda t, u: np.array([0.3 if t > 0.2 else 0.0, 0.0]))  # fmt: skip
        assert max(err.values()) <= C_DOUBLE
        assert abs(traj["fhat"][-1][0]) > 0.01  # the actuator fault is seen


def _many(k):
    """A plant whose drift needs k premises: tanh(c x1)/x1 for k different c."""
    return _two_state(
        lambda x1, x2, u, fa: [x2, -sum(ca.tanh((1 + 0.37 * j) * x1) for j in range(k)) + u + fa]
    )


def test_many_premises_warn_then_refuse():
    with pytest.warns(RuntimeWarning, match="found 7 premises"):
        ts = derive(_many(7), fidelity_samples=200)
    assert ts.r == 2**7
    with pytest.raises(DerivationError, match=r"needs 11 premises .*linearise at operating points"):
        derive(_many(11), fidelity_samples=200)


def test_declared_premises_still_take_precedence(ts_models):
    """The built-in manipulator declares its premise: unchanged, and the method says sector."""
    assert ts_models["manipulator"].method == "sector" and ts_models["manipulator"].premises[0].name == "mu"


# -- properties ----------------------------------------------------------------------------
_TERMS = [
    lambda c, x1, x2: c * x1 * x2,
    lambda c, x1, x2: c * x1**2,
    lambda c, x1, x2: c * x1 * x2**2,
    lambda c, x1, x2: c * ca.sin(x1),
    lambda c, x1, x2: c * ca.cos(x2) * x1,
    lambda c, x1, x2: c * ca.sin(x1) * ca.cos(x2),
    lambda c, x1, x2: c * ca.tanh(x2),
    lambda c, x1, x2: c * (ca.cos(x1) - 1),
]


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.integers(0, len(_TERMS) - 1), st.floats(-2, 2).filter(lambda v: abs(v) > 0.05)),
                min_size=1, max_size=3),
       st.integers(0, 10_000))  # fmt: skip
def test_ts_model_equals_the_nonlinear_drift(terms, seed):
    """Random polynomial and trigonometric drifts: the blended T-S drift equals the nonlinear drift at
    random points of the region, and the memberships are a convex sum."""

    def rows(x1, x2, u, fa):
        nl = sum(_TERMS[k](c, x1, x2) for k, c in terms)
        return [x2, -x1 - 0.5 * x2 + nl + u + fa]

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ts = derive(_two_state(rows), fidelity_samples=300, seed=seed)
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2, 2, (2, 200))
    U, F = rng.uniform(-1, 1, (1, 200)), rng.uniform(-1, 1, (1, 200))
    true = np.array(ts.plant.drift_function().map(200)(X, U, np.zeros((0, 200)), F))
    bl, _ = blended(ts, X, U, np.zeros((0, 200)), F, np.zeros((0, 200)))
    assert np.max(np.abs(true - bl)) <= ROUNDOFF * max(1.0, np.max(np.abs(true)))
    H = ts.memberships(X)
    assert np.all(H >= -1e-15) and np.allclose(H.sum(axis=0), 1.0, atol=1e-12)
