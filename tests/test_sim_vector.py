"""The lane emitter (issue #11): every operation against CasADi's own evaluation, the fallback to
CasADi's C for operations it does not know, and the random numbers drawn inside the C loop."""

from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pytest

from fte_casadi.errors import SimulationError
from fte_casadi.sim import _rng as rng
from fte_casadi.sim._vector import _CALL, _VEC, UnsupportedOperation, VectorEngine, emit, unsupported

NAN, INF = math.nan, math.inf
#: operand pairs (a, b): ordinary values, signed zeros, ties, NaN and infinities on either side
PAIRS = [(0.3, -1.2), (-0.7, 0.45), (2.5, 2.5), (-0.0, 0.0), (0.0, -0.0), (NAN, 1.0), (1.0, NAN), (NAN, NAN),
         (INF, -INF), (-INF, 3.0), (1e300, 1e-300), (4.0, 0.5), (-3.0, 2.0), (0.0, 0.0), (0.9, -0.99),
         (-1.5, -0.25)]  # fmt: skip


def _all_ops(a, b):
    """One expression per operation of the emitter's tables (in CasADi's own SX form)."""
    return [
        a + b, a - b, a * b, a / b, -a, a**2, a + a, 1 / a, a < b, a <= b, a == b, a != b,
        ca.logic_not(a), ca.logic_and(a, b), ca.logic_or(a, b), ca.if_else(a < b, a * 2, b),
        ca.if_else(b, a, 0), ca.fabs(a), ca.copysign(a, b), ca.sign(a), ca.fmin(a, b), ca.fmax(a, b),
        ca.exp(a), ca.log(a), ca.sqrt(a), ca.sin(a), ca.cos(a), ca.tan(a), ca.asin(a), ca.acos(a), ca.atan(a),
        ca.floor(a), ca.ceil(a), ca.erf(a), ca.sinh(a), ca.cosh(a), ca.tanh(a), ca.asinh(a), ca.acosh(a),
        ca.atanh(a), ca.log1p(a), ca.expm1(a), a**b, a**2.5, ca.fmod(a, b), ca.remainder(a, b),
        ca.atan2(a, b), ca.hypot(a, b), a * math.inf, a - math.inf, a + math.nan,
    ]  # fmt: skip


def _sample(exprs_of, nw: int = 1):
    """``(state, w, sh) -> (next, rec, incr)`` with ``state = [a, b]`` and ``rec = exprs_of(a, b)``."""
    s = ca.SX.sym("s", 2)
    w = ca.SX.sym("w", nw)
    sh = ca.SX.sym("sh", 1)
    rec = ca.vertcat(*exprs_of(s[0], s[1]))
    return ca.Function("t", [s, w, sh], [s, rec, ca.vertcat(s[0] * 0 + 1)])


def _run(eng, S0, nsamp=1, every=1, seed=0, path0=0, sqdt=1.0, damp=1.0):
    SH = np.zeros((nsamp, 1))
    return eng.run(path0, S0, seed, SH, sqdt, damp, 1e300, every)


def _same(got, want):
    """Equal values, NaN where NaN, and the same sign wherever the value is zero."""
    np.testing.assert_array_equal(got, want)
    z = want == 0
    np.testing.assert_array_equal(np.signbit(got[z]), np.signbit(want[z]))


@pytest.fixture(scope="module")
def ops_function():
    return _sample(_all_ops)


def test_the_test_function_covers_every_operation(ops_function):
    names = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}
    used = {names[ops_function.instruction_id(k)] for k in range(ops_function.n_instructions())}
    missing = (set(_VEC) | set(_CALL)) - used - {"OP_ASSIGN", "OP_LIFT"}
    assert not missing, missing
    assert unsupported(ops_function) == []


@pytest.mark.parametrize("casadi_c", [False, True], ids=["lane-vectors", "casadi-c"])
def test_every_operation_equals_casadi(ops_function, casadi_c):
    """Each operation on ordinary and special operands gives CasADi's value: NaN where CasADi has NaN,
    the C library's results for the calls, and signed zeros where they are defined (not fmin/fmax ties,
    which C leaves to the implementation)."""
    eng = VectorEngine(ops_function, [], name="fte_test_ops", casadi_c=casadi_c)
    S0 = np.array(PAIRS)
    _, acc, _, rec = _run(eng, S0)
    with np.errstate(all="ignore"):
        want = np.array([np.asarray(ops_function(s, 0.0, 0.0)[1]).ravel() for s in S0])
    got = rec[:, 0, :]
    tie = np.array([a == b for a, b in PAIRS])
    k_min = 20  # fmin, fmax: the 21st and 22nd expressions
    _same(np.delete(got, [k_min, k_min + 1], axis=1), np.delete(want, [k_min, k_min + 1], axis=1))
    np.testing.assert_array_equal(got[:, k_min : k_min + 2], want[:, k_min : k_min + 2])
    # fmin/fmax: the C library's choice on a tie of +0 and -0 (the second operand), NaN ignored
    for k, (a, b) in enumerate(PAIRS):
        lo, hi = got[k, k_min], got[k, k_min + 1]
        if math.isnan(a) or math.isnan(b):
            other = b if math.isnan(a) else a
            assert (math.isnan(lo) and math.isnan(other)) or lo == other == hi
        elif tie[k]:
            assert math.copysign(1, lo) == math.copysign(1, b) == math.copysign(1, hi)
    np.testing.assert_array_equal(acc, np.ones((len(PAIRS), 1)))


def test_an_unknown_operation_runs_through_casadis_c():
    """A lookup table (CasADi OP_CALL) cannot be written as lane vectors: the engine says so and runs
    CasADi's generated C lane by lane, with CasADi's values."""
    grid = np.linspace(-2, 2, 9)
    table = ca.interpolant("table", "linear", [grid], np.sin(grid))
    F = _sample(lambda a, b: [table(a) * b, a + b])
    assert unsupported(F) == ["OP_CALL"]
    with pytest.raises(UnsupportedOperation, match="OP_CALL"):
        emit(F, [])
    assert issubclass(UnsupportedOperation, SimulationError)  # a clean one-paragraph error in the CLI
    eng = VectorEngine(F, [], name="fte_test_call")
    assert "OP_CALL" in eng.note
    S0 = np.array([[0.3, 2.0], [-1.1, -0.5], [1.7, 3.0]])
    _, _, _, rec = _run(eng, S0)
    want = np.array([np.asarray(F(s, 0.0, 0.0)[1]).ravel() for s in S0])
    np.testing.assert_array_equal(rec[:, 0, :], want)


def test_the_random_numbers_are_the_twins_and_depend_on_seed_and_path_only():
    """dW and d as drawn inside the C loop equal :mod:`fte_casadi.sim._rng`'s numpy twin bit for bit,
    and path i's numbers do not depend on the chunk it runs in."""
    F = _sample(lambda a, b: [a, b], nw=3)  # rec = the state
    s, w, sh = (F.sx_in(i) for i in range(3))
    G = ca.Function("rngt", [s, w, sh], [ca.vertcat(w[0], w[1]), ca.vertcat(w[0], w[1], w[2]), ca.SX(1, 1)])
    eng = VectorEngine(G, [], name="fte_test_rng")
    nsamp, paths = 50, np.arange(11)
    S0 = np.zeros((len(paths), 2))
    _, _, _, rec = _run(eng, S0, nsamp=nsamp, seed=77, sqdt=1.0, damp=1.0)
    n, d = rng.step_numbers(77, paths, 0, nsamp, 2)
    np.testing.assert_array_equal(rec[:, :, 0], n)
    np.testing.assert_array_equal(rec[:, :, 1:], d)
    _, _, _, part = _run(eng, S0[:4], nsamp=nsamp, seed=77, path0=5)
    np.testing.assert_array_equal(part, rec[5:9])
    _, _, _, other = _run(eng, S0, nsamp=nsamp, seed=78)
    assert not np.any(other == rec)
