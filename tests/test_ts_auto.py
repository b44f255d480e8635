"""Automatic sector nonlinearity and linear plants (issue #10): fte_casadi/ts/_auto.py."""

from __future__ import annotations

import warnings

import casadi as ca
import mpmath as mp
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from plant_auto import linear, linear_scenario, manipulator_plain, two_state
from tolerances import C_DOUBLE, PAPER_A, PAPER_BOUND, ROUNDOFF

from fte_casadi.codegen import CStep, closed_loop_compare, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.design import design
from fte_casadi.errors import DerivationError, PlantError
from fte_casadi.plants import load_plant
from fte_casadi.sim import simulate
from fte_casadi.ts import derive, scheduling_from_measurements
from fte_casadi.ts._auto import TAYLOR_BAND, premise_form
from fte_casadi.ts._fidelity import blended

EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[1] / "examples"


@pytest.fixture(scope="module")
def plain_and_builtin(ts_models):
    return derive(manipulator_plain()), ts_models["manipulator"]


def test_plain_manipulator_gives_the_paper_model(plain_and_builtin):
    ts, ref = plain_and_builtin
    assert ts.r == 2 and len(ts.premises) == 1 and "automatically" in ts.method and ts.kind == "sector_auto"
    assert ts.to_dict()["premises_found_automatically"] is True
    pr = ts.premises[0]
    assert pr.expr == ref.premises[0].expr == "sin(theta_l)/theta_l"  # the built-in premise, same text
    assert (pr.min, pr.max) == (ref.premises[0].min, ref.premises[0].max)  # the same global bound search
    assert pr.min == pytest.approx(-0.2172336, abs=1e-6) and pr.max == pytest.approx(1.0, abs=1e-12)
    for a, b in zip(ts.local_models, ref.local_models):  # same rule order as the built-in plant
        for k in ("A", "B", "Bd", "Bf", "W"):
            np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=0, atol=1e-12)
    assert ts.local_models[0].A[3, 2] == pytest.approx(-22.83, abs=PAPER_A)
    assert ts.local_models[1].A[3, 2] == pytest.approx(-18.77, abs=PAPER_A)
    assert ts.local_models[1].W[3, 2] == pytest.approx(0.006 - 0.003 * 0.2172336, abs=PAPER_BOUND * 1e-3)
    assert ts.fidelity.max_abs_error <= ROUNDOFF and ts.fidelity.trajectory_max_abs_error <= ROUNDOFF
    assert ts.fidelity.trajectory_points == ref.fidelity.trajectory_points > 1
    doc = ts.to_dict()
    assert doc["premises_found_automatically"] and not ref.to_dict()["premises_found_automatically"]
    assert "z1 schedules A[w_l, theta_l], W[w_l, theta_l]" in doc["notes"]


@pytest.mark.slow
def test_plain_manipulator_designs_simulates_and_generates_like_the_builtin(
    plain_and_builtin, real_designs, tmp_path
):
    from fte_casadi.plants import SCENARIOS

    ts, _ = plain_and_builtin
    d = design(ts, sample_time=1e-3)
    ref = real_designs["manipulator"]
    assert d.certified
    for a, b in zip(d.K + d.L1 + (d.N,), ref.K + ref.L1 + (ref.N,)):  # the design is a function of the model
        assert np.max(np.abs(a - b)) <= 1e-6 * np.max(np.abs(b))
    sc = SCENARIOS["manipulator"]().until(4.0)
    m = simulate(d, ts.plant, sc, paths=4, seed=1, progress=False).metrics
    assert m["fault_rel_rms_error"][0] < 0.3
    if build.find_compiler() is not None:
        generate_c(d, tmp_path, sample_time=1e-3)
        lib = build.compile_shared(tmp_path, tmp_path / "lib.so")
        err, _ = closed_loop_compare(d, CStep(lib, d), 1e-3, 500, plant=ts.plant)
        assert max(err.values()) <= C_DOUBLE * 10


@pytest.mark.slow
def test_plain_pendulum_equals_the_premise_form():
    """examples/pendulum_plain.py (plain sin) and examples/pendulum_plant.py (premise by hand)."""
    plain = derive(load_plant(f"{EXAMPLES / 'pendulum_plain.py'}:pendulum"))
    hand = derive(load_plant(f"{EXAMPLES / 'pendulum_plant.py'}:pendulum"))
    assert plain.r == hand.r == 2 and plain.premises[0].expr == "sin(theta)/theta"
    for a, b in zip(plain.local_models, hand.local_models):
        for k in ("A", "B", "Bd", "Bf", "W"):
            np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=0, atol=1e-12)
    assert hand.notes == () and hand.method == "sector" and hand.kind == "sector"
    assert hand.to_dict()["premises_found_automatically"] is False


@pytest.mark.slow
def test_bilinear_and_saturation_derive_with_four_rules():
    """One box per premise (vertices="box") gives four rules; both premises depend on x1 alone, so the
    default covers their image (a curve) with a simplex of three (tests/test_ts_groups.py)."""
    plant = two_state(lambda x1, x2, u, fa: [x2, -x1 * x2 - 2 * ca.tanh(x1) - 0.5 * x2 + u + fa],
                      diff_rows=(lambda x1, x2: 0.01 * x1, 0.0))  # fmt: skip
    assert derive(plant).r == 3
    ts = derive(plant, vertices="box")
    assert ts.r == 4
    assert [p.expr for p in ts.premises] == ["x1", "tanh(x1)/x1"]  # the coefficients of x2 and x1 in row 2
    assert ts.fidelity.max_abs_error <= ROUNDOFF
    bounds = {p.expr: (p.min, p.max) for p in ts.premises}
    assert bounds["x1"] == pytest.approx((-2.0, 2.0), abs=1e-9)
    assert bounds["tanh(x1)/x1"] == pytest.approx((np.tanh(2.0) / 2.0, 1.0), abs=1e-6)
    # rule 1: x1 at its max and tanh(x1)/x1 at its max (the rule order of docs/interface.md)
    assert ts.local_models[0].A[1].tolist() == pytest.approx([-2.0, -2.5], abs=1e-12)
    assert ts.local_models[3].A[1].tolist() == pytest.approx([-np.tanh(2.0), 1.5], abs=1e-9)


def test_a_constant_written_with_round_off_is_no_premise():
    """A CSTR's reaction rate k(T) Ca less its value r* at the operating point, in deviations c, th: the piece at
    th = 0, k(T*) (Ca* + c) - r*, is linear in c, but its coefficient (k(T*) (Ca* + c) - r*) / c spans 6e-12 of
    itself over the region by round-off (r* = k(T*) Ca* computed apart). It is a constant
    (:data:`fte_casadi.ts._auto.CONSTANT_SPREAD`), not a premise: one premise and two rules (the temperature's),
    not four, and the model is exact."""
    k0, er, t_star, ca_star = 7.2e10, 8750.0, 350.0055, 0.4999183
    r_star = float(k0 * np.exp(-er / t_star) * ca_star)

    def rows(c, th, u, fa):
        r = k0 * ca.exp(-er / (t_star + th)) * (ca_star + c) - r_star
        return [-c - r, -th + 0.2 * r + u + fa]

    ts = derive(two_state(rows, region=((-0.2, 0.2), (-10.0, 10.0))))
    assert len(ts.premises) == 1 and "exp" in ts.premises[0].expr and ts.r == 2
    assert ts.fidelity.max_abs_error <= 1e-9


@pytest.mark.slow
def test_kinked_terms_are_exact():
    """fabs, fmin/fmax saturation and a leaky if_else: exact quotient, filled at 0 only."""
    ts = derive(two_state(lambda x1, x2, u, fa: [x2 - ca.fabs(x1), -ca.fmin(ca.fmax(x1, -1), 1) + u + fa
                                                 - ca.if_else(x2 > 0, x2, 0.1 * x2)]))  # fmt: skip
    assert ts.fidelity.max_abs_error <= ROUNDOFF  # derive also checked exactness at x = 0 and tiny x
    assert sorted((round(p.min, 9), round(p.max, 9)) for p in ts.premises) == [(-1, 0), (-1, 1), (0.5, 1)]


@pytest.mark.parametrize(
    "rows, region, message",
    [
        (lambda x1, x2, u, fa: [x2, -1 / x1 + u + fa], (-1.0, 1.0),
         r"drift row 'x2': the term -1/x1 is unbounded on the region: the argument x1 of its division is 0 there "
         r"\(it ranges over \[-1, 1\]"),
        (lambda x1, x2, u, fa: [x2, 1 / (x1 - 1) + u + fa], (-2.0, 2.0),
         r"drift row 'x2': the term 1/\(x1-1\) is unbounded on the region: the argument x1-1 of its division is 0"),
        (lambda x1, x2, u, fa: [x2, ca.tan(x1) + u + fa], (-2.0, 2.0),
         r"the term tan\(x1\) is unbounded on the region: the argument x1 of its tan reaches pi/2 \+ k pi"),
        (lambda x1, x2, u, fa: [x2, u / (x1 - 1) + fa], (-2.0, 2.0), r"drift row 'x2': the term u/\(x1-1\) is unbounded"),
        (lambda x1, x2, u, fa: [x2, ca.sqrt(x1) + u + fa], (0.0, 1.0),
         r"drift row 'x2': the coefficient of 'x1' in the term sqrt\(x1\): the coefficient sqrt\(x1\)/x1 is not finite "
         r"at x1 = 0"),
        (lambda x1, x2, u, fa: [x2, 0.1 * ca.sqrt(x1 + 1.5) + u + fa], (-2.0, 2.0),
         r"the term 0.1\*sqrt\(x1\+1.5\) is not real on the region: the argument x1\+1.5 of its sqrt is negative "
         r"there \(it ranges over \[-0.5, 3.5\]"),
        (lambda x1, x2, u, fa: [x2, ca.log(x1) + u + fa], (1.0, 2.0),
         r"drift row 'x2': the term log\(x1\) is not finite at x = 0"),
        (lambda x1, x2, u, fa: [x2, ca.sign(x1) + u + fa], (-2.0, 2.0),
         r"the automatic sector model is not exact: drift row 'x2' differs from the plain equations by 1 at x1 = "),
    ],
    ids=["1/x1", "1/(x1-1)", "tan", "u/(x1-1)", "sqrt", "sqrt<0", "log", "sign"],
)  # fmt: skip
@pytest.mark.slow
def test_terms_that_cannot_be_bounded_are_refused_by_name(rows, region, message):
    with pytest.raises(DerivationError, match=message) as exc:
        derive(two_state(rows, region=(region, (-2.0, 2.0))), fidelity_samples=2000)
    assert "Traceback" not in str(exc.value) and ("region" in str(exc.value) or "premise" in str(exc.value))


def test_input_entering_nonlinearly_is_refused_by_name():
    with pytest.raises(PlantError, match=r"drift row 'x2' is nonlinear in 'u': its derivative cos\(u\)"):
        two_state(lambda x1, x2, u, fa: [x2, ca.sin(u) + fa])


def test_an_input_times_an_unknown_input_is_refused_with_the_products_advice():
    """A chemostat's feed concentration fluctuating, D (Sf + d - S) (tests/plant_chemostat.py): a product of two
    signals has no function of one to invert; the advice is to take the product as one signal."""
    b = __import__("fte_casadi").PlantBuilder("feed")
    (s,) = b.states("S")
    (dil,) = b.inputs("D")
    (d,) = b.unknown_inputs("dSf")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([dil * (10.0 + d - s) - s])
    b.outputs([s + fs])
    b.region(S=(0.0, 1.0))
    with pytest.raises(PlantError) as exc:
        b.build()
    text = " ".join(str(exc.value).split())
    assert "drift row 'S' is nonlinear in 'D'" in text and "that term multiplies 'D' by 'dSf'" in text
    assert "an unknown input standing for D * dSf" in text and "sin(u)" not in text
    # an input times a fault: write the fault added; two inputs: their product is one input
    for rows, said in (
        (lambda x1, x2, u, fa: [x2, u * (1.0 + fa)], "write the fault where it enters, added (u + fa"),
        (lambda x1, x2, u, fa: [x2, u * u + fa], "v = sin(u)"),  # u * u: one signal's own nonlinearity
    ):
        with pytest.raises(PlantError) as exc:
            two_state(rows)
        assert said in " ".join(str(exc.value).split())
    # one signal's own nonlinearity keeps the advice to invert it
    with pytest.raises(PlantError, match=r"v = sin\(u\)"):
        two_state(lambda x1, x2, u, fa: [x2, ca.sin(u) + fa])


def test_uncovered_term_with_declared_premises_keeps_todays_error():
    b = __import__("fte_casadi").PlantBuilder("half")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    mu = b.premise("mu", ca.cos(x1))
    b.drift([x2, -mu * x1 - ca.sin(x2) + u + fa])
    b.outputs([x1, x2])
    b.region(x1=(-1, 1), x2=(-1, 1))
    with pytest.raises(PlantError, match=r"not covered by any premise.*or declare no premise at all: the premises are "
                                         r"then found in the plain equations"):  # fmt: skip
        b.build()


@pytest.mark.slow
def test_state_dependent_input_gain_becomes_a_premise():
    ts = derive(two_state(lambda x1, x2, u, fa: [x2, -x1 + (1 + 0.5 * ca.cos(x1)) * (u + fa)]))
    assert len(ts.premises) == 1 and ts.premises[0].expr == "1+(0.5*cos(x1))"  # the coefficient of u and fa
    assert [float(lm.B[1, 0]) for lm in ts.local_models] == pytest.approx(
        [1.5, 1 + 0.5 * np.cos(2.0)], abs=1e-9
    )
    assert ts.fidelity.max_abs_error <= ROUNDOFF


@pytest.mark.slow
def test_orientation_rule_one_weighs_most_at_the_origin():
    """The sign of a premise does not depend on how the user wrote it; rule 1 holds at the origin."""
    a = derive(two_state(lambda x1, x2, u, fa: [x2, -3 * ca.sin(x1) + u + fa]))
    b = derive(two_state(lambda x1, x2, u, fa: [x2, 3 * ca.sin(-x1) + u + fa]))
    for la, lb in zip(a.local_models, b.local_models):
        np.testing.assert_allclose(la.A, lb.A, rtol=0, atol=1e-12)
    assert b.premises[0].expr == "-(sin(-x1)/x1)" and (b.premises[0].min, b.premises[0].max) == pytest.approx(
        (np.sin(2.0) / 2.0, 1.0), abs=1e-9
    )
    cube = derive(two_state(lambda x1, x2, u, fa: [x2, -(x1**3) + u + fa]))  # premise x1^2, 0 at the origin
    assert cube.premises[0].expr == "-(x1^2)" and (cube.premises[0].min, cube.premises[0].max) == (-4.0, 0.0)
    assert cube.memberships(np.zeros(2)).tolist() == [1.0, 0.0]
    assert cube.local_models[0].A[1, 0] == 0.0 and cube.local_models[1].A[1, 0] == -4.0


@pytest.mark.slow
def test_singular_fill_is_exact_near_zero():
    """The quotient's removable singularity: coefficient values against 50-digit references near 0."""
    mp.mp.dps = 50
    funcs = {"exp": (ca.exp, mp.exp), "cos": (ca.cos, mp.cos), "1/(1+x^2)": (lambda v: 1 / (1 + v**2),
             lambda v: 1 / (1 + v**2)), "log(1+x+x^2)": (lambda v: ca.log(1 + v + v**2), lambda v: mp.log(1 + v + v**2))}  # fmt: skip
    xs = np.concatenate([[0.0], np.logspace(-17, 0, 60), -np.logspace(-17, 0, 60),
                         TAYLOR_BAND * (1 + np.array([-1e-6, 1e-6, -1e-6, 1e-6]) * [1, 1, -1, -1])])  # fmt: skip
    for name, (fc, fm) in funcs.items():
        plant = two_state(lambda x1, x2, u, fa, fc=fc: [x2, -x1 + fc(x1) + u + fa], region=((-1, 1), (-1, 1)))
        form = premise_form(plant)
        assert len(form.bounds) == 1, name
        z = ca.Function("z", [plant.x], [form.plant.z_exprs[0]])
        for v in xs:
            ref = mp.diff(fm, 0) if v == 0 else (fm(mp.mpf(v)) - fm(0)) / mp.mpf(v)
            sign = -1.0 if form.plant.z_texts[0].startswith("-(") else 1.0  # the premise may be negated
            got = sign * float(z([v, 0.0]))
            assert abs(got - float(ref)) <= 1e-11 * max(1.0, abs(float(ref))), (name, v)


@pytest.mark.slow
def test_linear_plant_is_one_rule_with_a_certified_design_simulation_and_working_c(tmp_path):
    ts = derive(linear())
    assert ts.r == 1 and ts.premises == () and ts.method == "linear (one rule)" and ts.kind == "linear"
    assert ts.fidelity.max_abs_error <= ROUNDOFF and ts.notes == (
        "no nonlinear term in the states: one rule (the plant is linear)",
    )
    np.testing.assert_array_equal(ts.memberships(np.zeros(2)), [1.0])
    np.testing.assert_array_equal(ts.memberships(np.ones((2, 5))), np.ones((1, 5)))
    sched, used = scheduling_from_measurements(ts)
    assert np.array(sched(np.ones(3), np.ones(2))).ravel().tolist() == [1.0] and used == []
    d = design(ts, sample_time=1e-3)
    assert d.certified and all(v < 0 for v in d.checks["lmi_max_eig"].values())
    assert d.checks["R_max_real_eig"] < 0 and d.checks["closed_loop_max_real_eig"] < 0
    m = simulate(d, ts.plant, linear_scenario(), paths=3, seed=2, progress=False).metrics
    assert all(e is not None and e < 0.5 for e in m["fault_rel_rms_error"]) and m["ftc_true_ratio"] < 0.8
    if build.find_compiler() is not None:
        generate_c(d, tmp_path, sample_time=1e-3)
        lib = build.compile_shared(tmp_path, tmp_path / "lib.so")
        err, traj = closed_loop_compare(d, CStep(lib, d), 1e-3, 800, plant=ts.plant,
                                        fault=lambda t, u: np.array([0.3 if t > 0.2 else 0.0, 0.0]))  # fmt: skip
        assert max(err.values()) <= C_DOUBLE
        assert abs(traj["fhat"][-1][0]) > 0.01  # the actuator fault is seen


def _many(k):
    """A plant whose drift needs k premises: tanh(c x1)/x1 for k different c."""
    return two_state(
        lambda x1, x2, u, fa: [x2, -sum(ca.tanh((1 + 0.37 * j) * x1) for j in range(k)) + u + fa]
    )


@pytest.mark.slow
def test_many_premises_warn_then_refuse():
    with pytest.warns(RuntimeWarning, match="found 7 premises"):
        ts = derive(_many(7), fidelity_samples=200, vertices="box")
    assert ts.r == 2**7
    with pytest.warns(RuntimeWarning, match="found 7 premises"):
        ts = derive(_many(7), fidelity_samples=200)  # all seven depend on x1 alone: one simplex
    assert ts.r <= 8 and ts.groups[0].polytope == "simplex" and ts.fidelity.max_abs_error <= ROUNDOFF
    with pytest.raises(DerivationError, match=r"needs 11 premises \(2048 rules\), more than 10: tanh\(x1\)/x1; "
                                              r".*Declare some premises yourself .*narrow the region.*linearise"):  # fmt: skip
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
    lambda c, x1, x2: c * ca.cos(x1),
    lambda c, x1, x2: c * ca.sin(x1 + 2 * x2),
    lambda c, x1, x2: c * x2**3,
]
_COEF = st.floats(-2, 2).filter(lambda v: abs(v) > 0.05)
_TERM = st.tuples(st.integers(0, len(_TERMS) - 1), _COEF)
#: the diffusion has no constant term (no additive noise): all terms but cos(x1)
_DIFF_TERM = st.tuples(st.sampled_from([k for k in range(len(_TERMS)) if k != 7]), _COEF)


@pytest.mark.slow
@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(_TERM, min_size=1, max_size=3), st.lists(_DIFF_TERM, max_size=1), st.integers(0, 10_000))
def test_ts_model_equals_the_nonlinear_equations(drift_terms, diff_terms, seed):
    """Random polynomial and trigonometric drifts and diffusions (bounded on the region): the blended T-S
    model equals the plain equations at random points, the memberships are a convex sum, and rule 1
    weighs most at the origin."""

    def rows(x1, x2, u, fa):
        nl = sum(_TERMS[k](c, x1, x2) for k, c in drift_terms)
        return [x2, -x1 - 0.5 * x2 + nl + u + fa]

    def diff(x1, x2):
        return 0.01 * x1 + sum(0.01 * _TERMS[k](c, x1, x2) for k, c in diff_terms)

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        ts = derive(two_state(rows, diff_rows=(0.0, diff)), fidelity_samples=300, seed=seed)
    rng = np.random.default_rng(seed)
    X = rng.uniform(-2, 2, (2, 200))
    U, F = rng.uniform(-1, 1, (1, 200)), rng.uniform(-1, 1, (1, 200))
    true = np.array(ts.plant.drift_function().map(200)(X, U, np.zeros((0, 200)), F))
    true_g = np.array(ts.plant.diffusion_function().map(200)(X, U, F, np.zeros((0, 200))))
    bl, bg = blended(ts, X, U, np.zeros((0, 200)), F, np.zeros((0, 200)))
    assert np.max(np.abs(true - bl)) <= ROUNDOFF * max(1.0, np.max(np.abs(true)))
    assert np.max(np.abs(true_g - bg)) <= ROUNDOFF
    H = ts.memberships(X)
    assert np.all(H >= 0.0) and np.allclose(H.sum(axis=0), 1.0, atol=1e-12)
    h0 = ts.memberships(np.zeros(2))
    if all(g.polytope == "box" for g in ts.groups):  # the box's rule order: rule 1 takes every premise's max
        assert h0[0] == pytest.approx(np.max(h0), abs=1e-12)


# -- the fidelity trajectory of an unstable or stiff open loop ---------------------------------
def test_fidelity_trajectory_of_an_escaping_open_loop_stops_and_says_so():
    """x1'' = 2 x1^2 - ... escapes in finite time; the adaptive integrator used to chase it with ever
    smaller steps for minutes (a hypothesis example found this). It stops once the state is 1000 region
    spans away, says why, and the model is still checked up to there at round-off."""
    ts = derive(
        two_state(lambda x1, x2, u, fa: [x2, -x1 - 0.5 * x2 + 2.0 * x1**2 + u + fa]), fidelity_samples=300
    )
    f = ts.fidelity
    assert f.trajectory_stop.startswith(
        "the open loop leaves the region: premise x1 leaves its bounds [-2, 2]"
    )
    assert "later the open loop escapes (beyond 1000 region spans" in f.trajectory_stop
    assert f.trajectory_horizon < 10.0
    assert 2 <= f.trajectory_points < 400 and f.trajectory_max_abs_error <= ROUNDOFF * 10


@pytest.mark.slow
def test_fidelity_trajectory_of_a_stiff_plant_is_integrated_by_a_stiff_method():
    """Poles near -1e4 and -1e-3: the horizon is 1000 s and RK45 would need some 1e7 steps (it ran for
    minutes). RK45 spends its share of the budget, LSODA integrates the whole horizon, and the sector
    model is compared along all of it; with too small a budget for both, the trajectory stops where it
    got to and says so."""
    from fte_casadi.ts._fidelity import _trajectory

    ts = derive(
        two_state(lambda x1, x2, u, fa: [-1e4 * x1 + ca.sin(x2) + u, -1e-3 * x2 + fa]), fidelity_samples=300
    )
    f = ts.fidelity
    assert (
        f.trajectory_stop == ""
        and f.trajectory_points == 400
        and f.trajectory_horizon == pytest.approx(1000.0)
    )
    assert f.trajectory_max_abs_error <= ROUNDOFF * 1e4 * 4
    plant = ts.plant
    fun = plant.drift_function()
    X, T, stop = _trajectory(
        lambda t, x: np.array(fun(x, 0.0, np.zeros(0), 0.0)).ravel(),
        np.array([1.0, 1.0]), 1000.0, 400, plant.region_lo, plant.region_hi, max_evaluations=60,
    )  # fmt: skip
    assert stop.startswith("stiff") and "LSODA" in stop and 2 <= T.size < 400 and X.shape == (2, T.size)
    assert T[-1] > T[-2] and np.all(np.isfinite(X))
