"""Tests of fte_casadi.design.core._sdp and .barrier: affine LMIs, the cvxpy assembly, the centring and phase 1."""

from __future__ import annotations

import numpy as np
import pytest
import scipy.linalg as sla

from fte_casadi.design.core._barrier import centre, phase1
from fte_casadi.design.core._sdp import (
    AffineLMI,
    CentringError,
    ConicProblem,
    Layout,
    Var,
    affine_lmi,
    margin_lmi,
)


def _layout():
    return Layout(Var("P", (2, 2), True), Var("y", (2,)), Var("t", ()))


A = np.array([[0.0, 1.0], [-2.0, -3.0]])


def _lyapunov(P, y, t):
    """``A^T P + P A + diag(y) <= 0``: affine in P, y."""
    return A.T @ P + P @ A + np.diag(y)


def test_layout_round_trip_and_symmetry():
    lay = _layout()
    assert lay.size == 3 + 2 + 1
    u = lay.unpack(np.arange(6.0))
    assert (
        np.array_equal(u["P"], [[0.0, 1.0], [1.0, 2.0]])
        and np.array_equal(u["y"], [3.0, 4.0])
        and u["t"] == 5.0
    )
    assert lay.index("y") == slice(3, 5)


def test_affine_extraction_equals_the_builder_everywhere():
    lay = _layout()
    L = affine_lmi("lyap", lay, _lyapunov)
    rng = np.random.default_rng(1)
    for _ in range(5):
        v = rng.standard_normal(lay.size)
        assert np.allclose(L.value(v), _lyapunov(**lay.unpack(v)), atol=1e-13)


def test_a_builder_that_is_not_affine_is_refused():
    with pytest.raises(RuntimeError, match="not affine"):
        affine_lmi("bad", _layout(), lambda P, y, t: P @ P)


def test_margin_lmi_is_base_plus_margin_term():
    lay = _layout()
    M = margin_lmi("m", lay, _lyapunov, margin=lambda P, y, t: np.eye(2) * (1 + t))
    v = np.random.default_rng(2).standard_normal(lay.size)
    u = lay.unpack(v)
    assert np.allclose(M.at(0.3).value(v), _lyapunov(**u) + 0.3 * np.eye(2) * (1 + u["t"]))


def _problem(margin=0.0):
    """``A^T P + P A + I <= 0``, ``I <= P <= 100 I``; objective trace(P) (y, t unused: a 3-unknown layout)."""
    lay = Layout(Var("P", (2, 2), True))
    lmis = [
        affine_lmi("lyap", lay, lambda P: A.T @ P + P @ A + (1 + margin) * np.eye(2)),
        affine_lmi("P >= I", lay, lambda P: (1 + margin) * np.eye(2) - P),
        affine_lmi("P <= 100 I", lay, lambda P: P - 100 * (1 - margin) * np.eye(2)),
    ]
    c = np.array([1.0, 0.0, 1.0])  # trace P (upper-triangle packing: P00, P01, P11)
    return lay, lmis, c


@pytest.mark.parametrize("solver", ["CLARABEL", "SCS"])
def test_conic_solve_counts_and_finds_a_feasible_point(solver):
    lay, lmis, c = _problem(margin=2e-3)
    prob = ConicProblem(lay, lmis, c)
    res = prob.solve(solver)
    assert res.status == "optimal" and prob.solves == 1
    assert all(np.linalg.eigvalsh(L.value(res.v))[-1] <= 1e-6 for L in lmis)


def test_infeasible_problem_is_reported_infeasible_not_failed():
    lay = Layout(Var("x", ()))
    lmis = [affine_lmi("x <= -1", lay, lambda x: np.array([[x + 1.0]])),
            affine_lmi("x >= 1", lay, lambda x: np.array([[1.0 - x]]))]  # fmt: skip
    res = ConicProblem(lay, lmis).solve("CLARABEL")
    assert res.infeasible and not res.failed


def test_centred_point_does_not_depend_on_the_start():
    """The centred point is a function of the LMIs alone: two different feasible starts give it to 1e-9."""
    lay, lmis, c = _problem(margin=1e-3)
    Pl = sla.solve_continuous_lyapunov(A.T, -np.eye(2))  # A^T Pl + Pl A = -I
    starts = [k * Pl[np.triu_indices(2)] for k in (10.0, 60.0)]
    for v in starts:
        assert all(np.linalg.eigvalsh(L.value(v))[-1] < 0 for L in lmis)
    a, b = (centre(lmis, c, v, eta=0.5).v for v in starts)
    assert np.max(np.abs(a - b)) <= 1e-9 * np.max(np.abs(a))
    # the gap equals eta times the objective: the point lies on the central path at mu = eta f / nu
    cen = centre(lmis, c, starts[0], eta=0.5)
    assert cen.mu * 6 == pytest.approx(0.5 * float(c @ cen.v), rel=1e-10)
    assert cen.min_slack > 0


def test_centring_refuses_an_infeasible_start():
    lay, lmis, c = _problem(margin=1e-3)
    with pytest.raises(CentringError, match="not strictly feasible"):
        centre(lmis, c, np.array([0.5, 0.0, 0.5]), eta=0.5)  # P < I


def test_phase1_decides_feasibility_both_ways():
    """x in [lo, hi] with x >= 1 (hard, satisfied at the start): feasible iff hi > 1."""
    lay = Layout(Var("x", ()))
    hard = [affine_lmi("x >= 1", lay, lambda x: np.array([[1.0 - x]]))]

    def soft(hi):
        return [affine_lmi("x <= hi", lay, lambda x: np.array([[x - hi]]))]

    v0 = np.array([5.0])
    ok = phase1(soft(2.0), hard, v0)
    assert ok is not None and 1.0 < ok[0] < 2.0
    assert phase1(soft(0.9), hard, v0) is None  # infeasible: proved by the duality bound
    assert phase1(soft(7.0), hard, v0) is not None  # the start itself is feasible


def test_affine_lmi_parameter_term():
    lay = Layout(Var("P", (2, 2), True))
    L = affine_lmi("decay", lay, lambda P: A.T @ P + P @ A, param=lambda P: 2 * P)
    v = np.array([2.0, 0.3, 1.0])
    P = lay.unpack(v)["P"]
    assert np.allclose(L.at(0.7).value(v), A.T @ P + P @ A + 1.4 * P)
    assert isinstance(L.at(0.0), AffineLMI)


def test_a_support_is_checked_and_keeps_the_map():
    """An LMI built on its support only equals the full extraction, and a builder (or its parameter term)
    that depends on an unknown outside the support it names fails loudly instead of giving a wrong LMI."""
    lay = Layout(Var("P", (2, 2), True), Var("r", (3,)))

    def b(P, r):
        return P + r[1] * np.eye(2) - np.eye(2)

    full = affine_lmi("b", lay, b, param=lambda P, r: 2 * P)
    part = affine_lmi("b", lay, b, param=lambda P, r: 2 * P, support=lay.support("P", ("r", 1)))
    np.testing.assert_array_equal(full.F, part.F)
    np.testing.assert_array_equal(full.G, part.G)
    with pytest.raises(RuntimeError, match="not affine"):
        affine_lmi("b", lay, b, support=lay.support("P", ("r", 0)))
    with pytest.raises(RuntimeError, match="not linear"):
        affine_lmi("b", lay, b, param=lambda P, r: r[2] * np.eye(2), support=lay.support("P", ("r", 1)))


# -- Kron terms: a symmetric unknown's part of an LMI given as sum_h A_h^T P B_h ------------------------------
def _kron_family(seed=3, n=4, k=7, r=3):
    """r LMIs ``sum_j (U_ij^T P V_ij + V_ij^T P U_ij) + W_i^T P W_i + rho_i S_i + s C_i - 50 I``, each with its own
    scalar rho_i (a different dense support per member, as rule i's gain scale in (46)), and a parameter
    term ``2 E^T P E`` (the decay rate's)."""
    rng = np.random.default_rng(seed)
    lay = Layout(Var("P", (n, n), True), Var("s", ()), Var("rho", (r,)))
    E = np.eye(n, k)
    lmis, plain = [], []
    for i in range(r):
        U, V, W = (rng.standard_normal((2, n, k)) for _ in range(3))
        W = W[0]
        S, C = (rng.standard_normal((k, k)) for _ in range(2))
        S, C = S + S.T, C + C.T

        def b(P, s, rho, U=U, V=V, W=W, S=S, C=C, i=i):
            return (
                sum(U[j].T @ P @ V[j] + V[j].T @ P @ U[j] for j in range(2))
                + W.T @ P @ W
                + rho[i] * S
                + s * C
                - 50 * np.eye(k)
            )

        sup = lay.support("P", "s", ("rho", i))
        terms = [(U[0], V[0]), (U[1], V[1]), (W, None)]
        lmis.append(affine_lmi(f"k{i}", lay, b, param=lambda P, s, rho: 2 * E.T @ P @ E, support=sup,
                               kron=("P", terms), kron_param=("P", [(E, E)])))  # fmt: skip
        plain.append(affine_lmi(f"k{i}", lay, b, param=lambda P, s, rho: 2 * E.T @ P @ E, support=sup))
    return lay, lmis, plain


def test_kron_terms_give_the_builders_coefficients():
    _, lmis, plain = _kron_family()
    for K, L in zip(lmis, plain):
        np.testing.assert_allclose(K.F, L.F, rtol=0, atol=1e-12)
        np.testing.assert_allclose(K.G, L.G, rtol=0, atol=1e-12)
        assert K.kron is not None and L.kron is None


def test_kron_terms_that_are_not_the_builders_are_refused():
    lay = Layout(Var("P", (2, 2), True))
    with pytest.raises(RuntimeError, match="Kron terms"):
        affine_lmi("lyap", lay, lambda P: A.T @ P + P @ A, kron=("P", [(np.eye(2), A.T)]))  # A, not A^T


def test_proportional_kron_terms_are_merged():
    """``(U, V) + (V, U)`` with ``V = c U`` is one term ``U^T P (2c U)``; the decay term joins ``P A``."""
    from fte_casadi.design.core._sdp import Kron

    U = np.arange(6.0).reshape(2, 3)
    K = Kron.of(0, [(U, 0.5 * U)], 2, 3)
    assert K.A.shape[0] == 1 and np.allclose(K.B[0], U)
    lay = Layout(Var("P", (2, 2), True))
    L = affine_lmi("decay", lay, lambda P: A.T @ P + P @ A, param=lambda P: 2 * P,
                   kron=("P", [(np.eye(2), A)]), kron_param=("P", [(np.eye(2), np.eye(2))]))  # fmt: skip
    assert L.kron.A.shape[0] == 2 and L.at(0.7).kron.A.shape[0] == 2


@pytest.mark.parametrize("p", [0.0, 0.8])
def test_kron_barrier_derivatives_equal_the_dense_ones(p):
    """The Kronecker route (gradient, Hessian over P's triangle, cross terms with each member's own scalar)
    gives the barrier's derivatives of the dense route to round-off."""
    from fte_casadi.design.core._barrier import _Barrier

    lay, lmis, plain = _kron_family()
    v = 0.05 * np.random.default_rng(4).standard_normal(lay.size)
    out = []
    for family in (lmis, plain):
        bar = _Barrier([L.at(p) for L in family], lay.size)
        fac = bar.factors(v)
        assert fac is not None
        out.append(bar.derivatives(fac))
    (gk, Hk), (gd, Hd) = out
    np.testing.assert_allclose(gk, gd, rtol=1e-11, atol=1e-11 * np.abs(gd).max())
    np.testing.assert_allclose(Hk, Hd, rtol=1e-11, atol=1e-11 * np.abs(Hd).max())


def test_kron_centring_and_phase1_give_the_dense_answers():
    lay, lmis, plain = _kron_family()
    c = np.zeros(lay.size)
    c[lay.index("rho")] = 1.0
    hard = [affine_lmi("|s| <= 1", lay, lambda P, s, rho: np.diag([s - 1.0, -1.0 - s])),
            affine_lmi("|rho| <= 10", lay, lambda P, s, rho: np.diag(np.r_[rho, -rho]) - 10 * np.eye(6)),
            affine_lmi("|P| <= 10", lay, lambda P, s, rho: np.block([[P - 10 * np.eye(4), 0 * P], [0 * P, -P - 10 * np.eye(4)]]))]  # fmt: skip
    v0 = np.zeros(lay.size)
    a, b = (phase1([L.at(0.0) for L in fam], hard, v0) for fam in (lmis, plain))
    assert a is not None and b is not None
    ca_, cb_ = (
        centre([L.at(0.0) for L in fam] + hard, c, v0, eta=0.5, floor=40.0).v for fam in (lmis, plain)
    )
    assert np.max(np.abs(ca_ - cb_)) <= 1e-8 * np.max(np.abs(cb_))


def test_phase1_on_a_growing_subset_decides_as_phase1_on_all():
    """phase1_active answers the same question as phase1 on every soft LMI: its point satisfies all of
    them strictly, and its 'no' (a subset without a point) is a 'no' for all. Here x <= hi_k for 20 soft
    LMIs with x >= 1 hard: feasible iff min hi_k > 1, decided by the one smallest hi_k among 20."""
    from fte_casadi.design.core._barrier import phase1_active

    lay = Layout(Var("x", ()))
    hard = [affine_lmi("x >= 1", lay, lambda x: np.array([[1.0 - x]]))]
    rng = np.random.default_rng(3)
    v0 = np.array([5.0])
    for lowest in (0.9, 1.2, 6.0):
        his = np.r_[rng.uniform(2.0, 9.0, 19), lowest]
        soft = [
            affine_lmi(f"x <= {h:g}", lay, lambda x, h=h: np.array([[x - h]])) for h in rng.permutation(his)
        ]
        full = phase1(soft, hard, v0)
        v, active = phase1_active(soft, hard, v0)
        assert (v is None) == (full is None) == (lowest <= 1.0)
        if v is not None:
            assert all(np.linalg.eigvalsh(L.value(v))[-1] < 0 for L in soft)
        assert len(active) < len(soft)  # a few decided it


def test_phase1_on_a_subset_with_tied_caps_gives_the_full_answers(monkeypatch):
    """The Kron family with 12 members (one scalar rho_i each, capped by an LMI of its own) and I <= P <= 10 I:
    the decay term makes it infeasible for large parameters. Taken two members at a time, with the caps tied
    to their members, the growing subset decides every value as phase 1 on all members does."""
    from fte_casadi.design.core import _barrier as barrier

    monkeypatch.setattr(barrier, "ACTIVE_ADD", 2)
    lay, lmis, _ = _kron_family(r=12)
    eye, zero = np.eye(4), np.zeros((4, 4))
    hard = [affine_lmi("|s| <= 1", lay, lambda P, s, rho: np.diag([s - 1.0, -1.0 - s])),
            affine_lmi("I <= P <= 10 I", lay, lambda P, s, rho: np.block([[P - 10 * eye, zero], [zero, eye - P]]))]  # fmt: skip
    caps = [affine_lmi(f"|rho_{i}| <= 10", lay, lambda P, s, rho, i=i: np.diag([rho[i] - 10.0, -rho[i] - 10.0]),
                       support=lay.support(("rho", i))) for i in range(len(lmis))]  # fmt: skip
    v0 = lay.pack(P=2 * eye)
    answers = []
    for p in (0.0, 10.0, 15.0, 30.0):
        soft = [L.at(p) for L in lmis]
        full = barrier.phase1(soft, hard + caps, v0)
        v, active = barrier.phase1_active(soft, hard, v0, tied=[[c] for c in caps])
        assert (v is None) == (full is None)
        if v is not None:
            assert all(np.linalg.eigvalsh(L.value(v))[-1] < 0 for L in soft + hard + caps)
        else:
            assert len(active) < len(lmis)  # a subset proved it
        answers.append(v is not None)
    assert answers == [True, True, False, False]
