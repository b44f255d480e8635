"""T-S derivation: sector nonlinearity, linearisation, bounds, rule order, memberships, fidelity."""

import casadi as ca
import numpy as np
import pytest
from tolerances import PAPER_A, PAPER_A_TANK, PAPER_B, PAPER_BOUND, PAPER_W, ROUNDOFF

from fte_casadi import PlantBuilder
from fte_casadi.errors import DerivationError
from fte_casadi.plants import manipulator, three_tank
from fte_casadi.ts import derive
from fte_casadi.ts._memberships import rule_vertices, sector_memberships
from fte_casadi.ts._premise_bounds import premise_bounds

PAPER_MANIP_A1_32, PAPER_MANIP_A2_32 = -22.83, -18.77
TANK_A = [
    [[-0.0216, 0, 0.0216], [0, -0.0352, 0.0216], [0.0216, 0.0216, -0.0432]],
    [[-0.0153, 0, 0.0153], [0, -0.0289, 0.0153], [0.0153, 0.0153, -0.0305]],
    [[-0.0125, 0, 0.0125], [0, -0.0261, 0.0125], [0.0125, 0.0125, -0.0249]],
]


@pytest.fixture(scope="module")
def manip():
    return derive(manipulator())


@pytest.fixture(scope="module")
def tank():
    return derive(three_tank())


def test_manipulator_local_models_match_paper(manip):
    A_common = np.array([[0, 1, 0, 0], [-48.6, -1.25, 48.6, 0], [0, 0, 0, 1], [19.5, 0, 0, 0]])
    for lm, a32 in zip(manip.local_models, (PAPER_MANIP_A1_32, PAPER_MANIP_A2_32)):
        expect = A_common.copy()
        expect[3, 2] = a32
        np.testing.assert_allclose(lm.A, expect, atol=PAPER_A)
        np.testing.assert_allclose(lm.B, [[0], [21.6], [0], [0]], atol=PAPER_B)
        np.testing.assert_allclose(lm.Bd, [[0.1], [-0.2], [0.3], [0.5]], atol=PAPER_B)
        np.testing.assert_allclose(lm.Bf, np.hstack([lm.B, np.zeros((4, 1))]), atol=0)
        np.testing.assert_array_equal(lm.a, np.zeros(4))
    W1 = [[0, 0.0006, 0, 0], [-0.002, -0.0001, 0.001, 0], [0, 0, 0, 0.0005], [-0.0004, 0, 0.009, 0]]
    W2 = np.array(W1)
    W2[3, 2] = 0.006 - 0.003 * 0.217234  # = 0.00535 by derivation (the paper prints 0.005)
    np.testing.assert_allclose(manip.local_models[0].W, W1, atol=PAPER_W)
    np.testing.assert_allclose(manip.local_models[1].W, W2, atol=PAPER_W)
    np.testing.assert_allclose(manip.Df, [[0, 1], [0, 0], [0, 0]])


def test_manipulator_premise_bounds_and_fidelity(manip):
    (pr,) = manip.premises
    assert pr.min == pytest.approx(-0.217234, abs=PAPER_BOUND)
    assert pr.max == pytest.approx(1.0, abs=PAPER_BOUND)
    assert pr.min == pytest.approx(-0.2172336282, abs=1e-8)  # global minimum of sinc at 4.4934
    assert manip.fidelity.max_abs_error <= ROUNDOFF
    assert manip.fidelity.trajectory_max_abs_error <= ROUNDOFF
    assert manip.fidelity.samples >= 10_000


def test_three_tank_local_models_match_paper(tank):
    assert tank.r == 3
    for lm, A in zip(tank.local_models, TANK_A):
        np.testing.assert_allclose(lm.A, A, atol=PAPER_A_TANK)
        np.testing.assert_allclose(lm.B, np.vstack([np.eye(2), np.zeros((1, 2))]) / 154, atol=1e-12)
        np.testing.assert_allclose(lm.Bf, [[0], [1 / 154], [0]], atol=1e-12)
    # the affine offsets are kept (a_k = f(x_k, u_k) - A_k x_k - B u_k, with f = 0 at the equilibria)
    plant = tank.plant
    for k, lm in enumerate(tank.local_models):
        xk, uk = plant.operating_points[k], plant.operating_inputs[k]
        np.testing.assert_allclose(lm.a, -(lm.A @ xk + lm.B @ uk), atol=1e-9)


def test_three_tank_fidelity_is_a_real_number(tank):
    f = tank.fidelity
    assert 1e-3 < f.drift_max_abs_error < 1.0  # linearisation error is real, not round-off
    assert f.diffusion_max_abs_error <= ROUNDOFF  # the diffusion is blended exactly
    # at the operating points the blended model is exact
    plant = tank.plant
    fd = plant.drift_function()
    for k in range(3):
        xk, uk = plant.operating_points[k], plant.operating_inputs[k]
        np.testing.assert_allclose(np.array(fd(xk, uk, 0, 0)).ravel(), 0, atol=1e-10)


def test_bounds_find_extremum_between_sample_points():
    # a narrow dip of width ~1e-4 centred off the grid: sampling alone misses most of its depth
    x = ca.SX.sym("x", 1)
    c = 0.123456789
    e = -ca.exp(-(((x[0] - c) / 3e-5) ** 2))
    mn, mx, idx, gap = premise_bounds("dip", e, x, np.array([-10.0]), np.array([10.0]), ["x"])
    assert mn == pytest.approx(-1.0, abs=1e-6)
    assert mx == pytest.approx(0.0, abs=1e-9)
    assert idx == (0,)


def test_bounds_two_dimensional():
    x = ca.SX.sym("x", 2)
    e = ca.sin(x[0]) * ca.cos(x[1])
    mn, mx, idx, gap = premise_bounds("sc", e, x, np.array([0.0, 0.0]), np.array([3.0, 3.0]), ["a", "b"])
    assert mx == pytest.approx(1.0, abs=1e-6)  # at (pi/2, 0)
    assert mn == pytest.approx(np.cos(3.0), abs=1e-6)  # at (pi/2, 3), on the boundary


def test_nan_premise_refused():
    x = ca.SX.sym("x", 1)
    with pytest.raises(DerivationError, match="not finite at x = 0"):
        premise_bounds("mu", ca.sin(x[0]) / x[0], x, np.array([-1.0]), np.array([1.0]), ["x"])


def test_rule_order_two_premises():
    v = rule_vertices([0.0, -1.0], [1.0, 2.0])
    # first premise slowest, each taking max then min
    np.testing.assert_array_equal(v, [[1, 2], [1, -1], [0, 2], [0, -1]])


@pytest.mark.parametrize("q", [1, 2, 3])
def test_memberships_convex_and_reproduce_premises(q):
    rng = np.random.default_rng(q)
    mins, maxs = -rng.random(q), 1 + rng.random(q)
    F = sector_memberships(mins, maxs)
    V = rule_vertices(mins, maxs)
    for _ in range(50):
        z = mins + (maxs - mins) * rng.random(q)
        h = np.array(F(z)).ravel()
        assert np.all(h >= 0) and h.sum() == pytest.approx(1.0, abs=1e-14)
        np.testing.assert_allclose(h @ V, z, atol=1e-12)  # blending the vertices gives the premises back
    # outside the bounds the premises saturate: still a convex sum
    h = np.array(F(maxs + 10)).ravel()
    assert np.all(h >= 0) and h.sum() == pytest.approx(1.0)


def test_triangular_memberships_of_three_tank(tank):
    for x1, expect in [
        (15, [1, 0, 0]),
        (17.5, [0.5, 0.5, 0]),
        (20, [0, 1, 0]),
        (22.5, [0, 0.5, 0.5]),
        (25, [0, 0, 1]),
        (40, [0, 0, 1]),
        (3, [1, 0, 0]),
    ]:
        np.testing.assert_allclose(tank.memberships(np.array([x1, 10, 15])), expect, atol=1e-12)


@pytest.mark.slow
def test_two_premise_plant_derives_four_rules_exactly():
    b = PlantBuilder("two")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    m1 = b.premise("m1", ca.cos(x1))
    m2 = b.premise("m2", x2**2)
    b.drift([x2, -m1 * x1 - m2 * x2 + u + fa])
    b.outputs([x1, x2])
    b.region(x1=(-1.0, 1.0), x2=(-2.0, 2.0))
    ts = derive(b.build())
    assert ts.r == 4
    assert ts.premises[1].min == pytest.approx(0.0, abs=1e-9) and ts.premises[1].max == pytest.approx(4.0)
    assert ts.local_models[0].A[1, 0] == pytest.approx(-1.0) and ts.local_models[0].A[1, 1] == pytest.approx(
        -4.0
    )
    assert ts.local_models[3].A[1, 0] == pytest.approx(-np.cos(1.0)) and ts.local_models[3].A[
        1, 1
    ] == pytest.approx(0.0)
    assert ts.fidelity.max_abs_error <= ROUNDOFF


def test_premise_squared_refused():
    b = PlantBuilder("sq")
    (x,) = b.states("x")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa")
    m = b.premise("m", ca.sin(x))
    b.drift([-(m**2) * x + u + fa])
    b.outputs([x])
    b.region(x=(-1.0, 1.0))
    with pytest.raises(DerivationError, match="nonlinearly on premise 'm'"):
        derive(b.build())


def test_the_direct_call_gives_the_functions_numbers_also_for_a_sparse_output():
    """ts/_direct.py: the zero-copy call of the fidelity trajectory and the premises' searches gives what the
    Function gives, to the bit, and densifies an output with structural zeros instead of misreading it."""
    import casadi as ca

    from fte_casadi.ts._direct import direct

    x = ca.SX.sym("x", 3)
    f = ca.Function("f", [x], [ca.vertcat(ca.sin(x[1]), x[0] * x[2]), ca.gradient(x[0] ** 2 * x[2], x)])
    xm = ca.MX.sym("x", 2)
    g = ca.Function("g", [xm], [ca.vertcat(ca.exp(xm[0]), ca.MX(1, 1), xm[1])])  # a structural zero
    assert g.nnz_out(0) == 2
    rng = np.random.default_rng(0)
    for fun, n in ((f, 3), (g, 2)):
        call = direct(fun)
        for _ in range(3):
            v = rng.standard_normal(n)
            for got, want in zip(call(v), fun.call([v])):
                np.testing.assert_array_equal(got, np.array(ca.densify(want)).ravel(order="F"))
