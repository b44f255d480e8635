"""The fast Monte Carlo mode (issue #20): ``simulate(..., exact=False)``, ``--fast-math``.

Tolerance (docs/simulation.md, "The fast mode"): every recorded signal of every run within
``FAST_REL`` of the exact mode's, relative to that signal component's largest magnitude over the
paths and the horizon, and every number of the metrics document within ``FAST_REL`` relative.
Where it comes from: the fast mode changes each rounding by at most half an ulp (a fused
multiply-add rounds once instead of twice) and each ``sin``/``log`` by libmvec's documented bound
(at most 4 ulp, about 1e-15 relative); the closed loop is stable, so these perturbations are not
amplified exponentially but accumulate over the 10 001 samples like a filtered random walk.
Measured on the manipulator's scenario (64 paths, all samples): the largest such difference is 8e-13
(a fault estimate, whose scale is 0.03), states 2e-14, metrics 1e-13; on the three-tank's 2e-13.
``FAST_REL = 1e-9`` keeps three orders of magnitude for other seeds, paths and CPUs (libmvec's AVX2
and AVX-512 variants differ in the last bits).
"""

from __future__ import annotations

import dataclasses
import json
import math
import platform

import casadi as ca
import numpy as np
import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.errors import ParameterError
from fte_casadi.plants import SCENARIOS
from fte_casadi.sim import _rng as rng
from fte_casadi.sim import simulate
from fte_casadi.sim._engine import SCALES, Prepared, resolve_dt
from fte_casadi.sim._vector import _VMATH, FAST_FLAGS, FLAGS, VectorEngine

FAST_REL = 1e-9
SIGNALS = ("x", "xbarhat", "f", "u", "y", "yc")
RUNS = ("free", "no_ftc", "ftc")
LIBMVEC = platform.system() == "Linux" and platform.machine() in ("x86_64", "AMD64")


def _numbers(m, pre=""):
    """Every number of a metrics document by its path (``wall_s`` left out)."""
    out = {}
    if isinstance(m, dict):
        for k, v in m.items():
            if k != "wall_s":
                out.update(_numbers(v, f"{pre}.{k}"))
    elif isinstance(m, list):
        for i, v in enumerate(m):
            out.update(_numbers(v, f"{pre}[{i}]"))
    elif isinstance(m, (int, float)) and not isinstance(m, bool):
        out[pre] = float(m)
    return out


def _close_metrics(a: dict, b: dict, rel: float) -> float:
    na, nb = _numbers(a), _numbers(b)
    assert na.keys() == nb.keys()
    worst = 0.0
    for k, v in na.items():
        assert math.isclose(v, nb[k], rel_tol=rel, abs_tol=0.0), (k, v, nb[k])
        if v:
            worst = max(worst, abs(v - nb[k]) / abs(v))
    return worst


@pytest.mark.slow
# the three-tank (8 s) repeats the manipulator's check on another plant: `pytest -m heavy`
@pytest.mark.parametrize(
    "name,paths", [("manipulator", 16), pytest.param("three-tank", 8, marks=pytest.mark.heavy)]
)
def test_fast_equals_exact_within_the_tolerance(plants, real_designs, name, paths):
    """The paper's scenario in full (both fault windows): trajectories and metrics within FAST_REL,
    and not bit for bit (the fast mode did run)."""
    plant, design, sc = plants[name], real_designs[name], SCENARIOS[name]()
    kw = dict(paths=paths, seed=3, progress=False, record_all=True, record_every=1)
    ex = simulate(design, plant, sc, **kw)
    fa = simulate(design, plant, sc, exact=False, **kw)
    assert ex.metrics["exact"] is True and fa.metrics["exact"] is False
    worst, differs = 0.0, False
    for run in RUNS:
        for sig in SIGNALS:
            a, b = getattr(getattr(ex, run), sig), getattr(getattr(fa, run), sig)
            assert np.all(np.isfinite(b))
            scale = np.max(np.abs(a), axis=(0, 1))
            diff = np.max(np.abs(a - b), axis=(0, 1))
            assert np.all(diff <= FAST_REL * scale), (run, sig, diff, scale)
            differs |= bool(np.any(diff > 0))
            worst = max(worst, float(np.max(diff / np.where(scale > 0, scale, 1.0))))
    assert differs and worst > 0  # contraction and libmvec changed some last bits: the fast engine ran
    assert np.abs(fa.ftc.f).max() > 0  # the faults acted
    _close_metrics(ex.metrics, fa.metrics, FAST_REL)
    assert any("fast mode" in n for n in fa.notes) and not any("fast mode" in n for n in ex.notes)


def _short(T=1.0):
    sc = SCENARIOS["manipulator"]()
    return dataclasses.replace(sc, T=1.0, faults=tuple(dataclasses.replace(f, start=f.start / 10, stop=f.stop / 10)
                                                        for f in sc.faults)).until(T)  # fmt: skip


@pytest.mark.slow
def test_fast_mode_does_not_depend_on_chunks_or_threads(plants, real_designs):
    """Every path runs the same instruction sequence whatever lane and chunk it lands in: metrics and
    recorded trajectories bit for bit equal for any chunk size (partial lanes included) and threads."""
    plant, design, sc = plants["manipulator"], real_designs["manipulator"], _short()
    kw = dict(paths=37, seed=4, progress=False, exact=False, record_all=True, record_every=7)
    runs = [simulate(design, plant, sc, chunk=256, threads=2, **kw), simulate(design, plant, sc, chunk=5, threads=1, **kw),
            simulate(design, plant, sc, chunk=3, threads=2, **kw), simulate(design, plant, sc, threads=3, **kw)]  # fmt: skip
    docs = [dict(r.metrics) for r in runs]
    for m in docs:
        m.pop("wall_s")
    assert all(m == docs[0] for m in docs) and docs[0]["exact"] is False
    for r in runs[1:]:
        for run in RUNS:
            for sig in SIGNALS:
                np.testing.assert_array_equal(
                    getattr(getattr(r, run), sig), getattr(getattr(runs[0], run), sig)
                )
    # the examples recorded again after the run (not by the chunks) are the same numbers too
    ex = simulate(
        design, plant, sc, paths=37, seed=4, progress=False, exact=False, record_paths=5, record_every=7
    )
    np.testing.assert_array_equal(ex.ftc.xbarhat, runs[0].ftc.xbarhat[:5])


@pytest.mark.slow
def test_fast_mode_on_a_cluster_equals_in_process(plants, real_designs):
    distributed = pytest.importorskip("distributed")
    plant, design, sc = plants["manipulator"], real_designs["manipulator"], _short()
    kw = dict(paths=40, seed=2, progress=False, exact=False)
    here = dict(simulate(design, plant, sc, chunk=8, **kw).metrics)
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as c:
        there = dict(simulate(design, plant, sc, chunk=16, scheduler=c.scheduler_address, **kw).metrics)
    here.pop("wall_s"), there.pop("wall_s")
    assert here == there and there["exact"] is False


def _unary_inputs(f: str) -> np.ndarray:
    g = np.random.default_rng(7)
    lo, hi = {"log": (1e-3, 50.0), "log1p": (-0.9, 50.0), "acosh": (1.0, 50.0), "asin": (-1.0, 1.0),
              "acos": (-1.0, 1.0), "atanh": (-0.99, 0.99), "exp": (-30.0, 30.0), "expm1": (-5.0, 5.0),
              "sinh": (-20.0, 20.0), "cosh": (-20.0, 20.0)}.get(f, (-20.0, 20.0))  # fmt: skip
    return g.uniform(lo, hi, 64)


def test_vector_math_is_within_libmvecs_bound_of_the_c_library():
    """Each function the fast mode takes from libmvec, on 64 arguments (8 lane vectors): within 4 ulp
    of the C library's result (glibc's documented bound for libmvec), the ground of FAST_REL."""
    s = ca.SX.sym("s", 2)
    w, sh = ca.SX.sym("w", 1), ca.SX.sym("sh", 1)
    a, b = s[0], s[1]
    ops = {"exp": ca.exp(a), "log": ca.log(a), "sin": ca.sin(a), "cos": ca.cos(a), "tan": ca.tan(a),
           "asin": ca.asin(a), "acos": ca.acos(a), "atan": ca.atan(a), "erf": ca.erf(a), "sinh": ca.sinh(a),
           "cosh": ca.cosh(a), "tanh": ca.tanh(a), "asinh": ca.asinh(a), "acosh": ca.acosh(a),
           "atanh": ca.atanh(a), "log1p": ca.log1p(a), "expm1": ca.expm1(a), "pow": a**b, "atan2": ca.atan2(a, b),
           "hypot": ca.hypot(a, b)}  # fmt: skip
    assert set(ops) == set(_VMATH.values())
    # one engine for all of them (one compile): function k reads state entries 2k, 2k + 1 and records entry k
    names = list(ops)
    S = ca.SX.sym("S", 2 * len(names))
    rec = [ca.substitute(ops[f], s, S[2 * k : 2 * k + 2]) for k, f in enumerate(names)]
    F = ca.Function("vm", [S, w, sh], [S, ca.vertcat(*rec), ca.SX(1, 1)])
    eng = VectorEngine(F, [], name="fte_test_vm", exact=False)
    if LIBMVEC:
        assert eng.vmath and all(f"fte_v_{f}(" in eng.source for f in names)
    y = np.random.default_rng(8).uniform(-3.0, 3.0, 64)
    S0 = np.column_stack([c for f in names for c in (_unary_inputs(f if f != "pow" else "log"), y)])
    _, _, _, got = eng.run(0, S0, 0, np.zeros((1, 1)), 1.0, 0.0, 1e300, 1)
    for k, f in enumerate(names):
        G = ca.Function("one", [s], [ops[f]])
        want = np.array([float(G(r)) for r in S0[:, 2 * k : 2 * k + 2]])
        err = np.abs(got[:, 0, k] - want)
        assert np.all(err <= 4 * np.spacing(np.abs(want))), (f, err.max())


def test_the_random_numbers_are_the_same_uniforms():
    """The fast mode draws the same uniforms (integer lane vectors; exact conversions) and the same
    normals to rounding (the central formula contracted into fused multiply-adds, the tails through
    libmvec's log); path i's numbers do not depend on its chunk."""
    s, w, sh = ca.SX.sym("s", 2), ca.SX.sym("w", 3), ca.SX.sym("sh", 1)
    G = ca.Function("rngt", [s, w, sh], [s, ca.vertcat(w[0], w[1], w[2]), ca.SX(1, 1)])
    eng = VectorEngine(G, [], name="fte_test_rng", exact=False)
    nsamp, paths = 200, np.arange(13)
    S0 = np.zeros((len(paths), 2))
    _, _, _, rec = eng.run(0, S0, 77, np.zeros((nsamp, 1)), 1.0, 1.0, 1e300, 1)
    n, d = rng.step_numbers(77, paths, 0, nsamp, 2)
    np.testing.assert_array_equal(rec[:, :, 1:], d)
    assert np.all(np.abs(rec[:, :, 0] - n) <= 8 * np.spacing(np.abs(n)))
    assert np.sum(np.abs(n) > 1.44) > 100  # the tails (|p - 1/2| > 0.425) were drawn
    _, _, _, part = eng.run(5, S0[:4], 77, np.zeros((nsamp, 1)), 1.0, 1.0, 1e300, 1)
    np.testing.assert_array_equal(part, rec[5:9])


def test_exact_mode_is_unchanged_and_the_mode_is_in_the_cache_key(plants, lqr_designs):
    """The exact engine keeps its flags and source (no vector math, no contraction); the fast one is a
    different library (its flags and source are in the cache key)."""
    assert "-ffp-contract=off" in FLAGS and "-ffp-contract=fast" in FAST_FLAGS
    assert "-ffast-math" not in FAST_FLAGS  # NaN and infinities kept: the divergence check needs them
    plant, design, sc = plants["manipulator"], lqr_designs["manipulator"], _short(0.1)
    dt, nsteps, _ = resolve_dt(design, sc, None)
    ex = Prepared(design, plant, sc, dt, nsteps, dict(SCALES))
    fa = Prepared(design, plant, sc, dt, nsteps, dict(SCALES), exact=False)
    assert "fte_v_" not in ex.engine.source and "fte_v_sin(" in fa.engine.source
    assert ex.engine.lib._name != fa.engine.lib._name
    assert ex.exact and not fa.exact


def test_bad_mode_is_refused(plants, lqr_designs):
    plant, design, sc = plants["manipulator"], lqr_designs["manipulator"], _short(0.1)
    with pytest.raises(ParameterError, match="exact must be True or False"):
        simulate(design, plant, sc, paths=2, seed=0, progress=False, exact="no")
    dt, nsteps, _ = resolve_dt(design, sc, None)
    prep = Prepared(design, plant, sc, dt, nsteps, dict(SCALES))
    with pytest.raises(ParameterError, match="prepare the engine in the mode of the run"):
        simulate(design, plant, sc, paths=2, seed=0, progress=False, exact=False, prepared=prep)


@pytest.mark.slow
def test_cli_fast_math_on_simulate_and_sweep():
    base = ["simulate", "manipulator", "--paths", "16", "--seed", "1", "--json", "--quiet"]
    a = CliRunner().invoke(main, base)
    b = CliRunner().invoke(main, base + ["--fast-math"])
    assert a.exit_code == 0 and b.exit_code == 0, (a.output, b.output)
    ma, mb = json.loads(a.stdout), json.loads(b.stdout)
    assert ma["exact"] is True and mb["exact"] is False
    _close_metrics(ma, mb, FAST_REL)
    txt = CliRunner().invoke(main, base[:-2] + ["--quiet", "--fast-math"])
    assert txt.exit_code == 0 and "note: fast mode" in txt.stdout
    sw = ["sweep", "manipulator", "--vary", "fault_scale=0.5,1", "--paths", "8", "--seed", "1", "--json",
          "--quiet"]  # fmt: skip
    c = CliRunner().invoke(main, sw + ["--fast-math"])
    assert c.exit_code == 0, c.output
    pts = json.loads(c.stdout)
    assert [p["metrics"]["exact"] for p in pts] == [False, False]


@pytest.mark.parametrize("exact", [True, False], ids=["exact", "fast"])
def test_a_path_alone_in_its_chunk_gets_the_same_numbers(plants, real_designs, exact):
    """A chunk of one path (37 = 12 x 3 + 1; chunk=1) starts from the same observer state as in a larger
    chunk (numpy's product of a single row takes another BLAS route; found by this file's chunk test)."""
    plant, design, sc = plants["manipulator"], real_designs["manipulator"], _short(0.3)
    kw = dict(paths=37, seed=4, progress=False, exact=exact, record_all=True, record_every=3)
    runs = [simulate(design, plant, sc, chunk=c, threads=1, **kw) for c in (256, 3, 1)]
    for r in runs[1:]:
        np.testing.assert_array_equal(r.ftc.xbarhat, runs[0].ftc.xbarhat)
        np.testing.assert_array_equal(r.no_ftc.xbarhat, runs[0].no_ftc.xbarhat)
        a, b = dict(r.metrics), dict(runs[0].metrics)
        a.pop("wall_s"), b.pop("wall_s")
        assert a == b


@pytest.mark.skipif(not LIBMVEC, reason="the AVX2 and AVX-512 variants are x86-64 only")
@pytest.mark.parametrize(
    "isa", [(), ("-mno-avx512f",), ("-mno-avx512f", "-mno-avx2")], ids=["native", "avx2", "no-vmath"]
)
def test_every_vector_width_is_close_and_split_free(plants, real_designs, monkeypatch, isa):
    """The fast engine as compiled for AVX-512 (libmvec's 8-lane variants), AVX2 (two 4-lane calls per
    lane vector) and without either (the C library lane by lane): each within FAST_REL of the exact
    mode, and each gives the same numbers for a split of the paths at an odd place."""
    from fte_casadi.sim import _vector as vector

    monkeypatch.setattr(vector, "FAST_FLAGS", vector.FAST_FLAGS + isa)
    plant, design, sc = plants["manipulator"], real_designs["manipulator"], _short(1.0)
    dt, nsteps, _ = resolve_dt(design, sc, None)
    ex = Prepared(design, plant, sc, dt, nsteps, dict(SCALES))
    fa = Prepared(design, plant, sc, dt, nsteps, dict(SCALES), exact=False)
    S0 = ex.initial_states(np.arange(21), 5)
    args = (5, ex.SH, ex.sqdt, ex.damp, 1e6)
    s_ex, acc_ex, _, _ = ex.engine.run(0, S0, *args)
    s_fa, acc_fa, div, _ = fa.engine.run(0, S0, *args)
    assert np.all(div < 0)
    scale = np.max(np.abs(s_ex), axis=0)
    assert np.all(np.abs(s_fa - s_ex) <= FAST_REL * scale)
    assert np.all(np.abs(acc_fa - acc_ex) <= FAST_REL * np.abs(acc_ex))
    a, acc_a, _, _ = fa.engine.run(0, S0[:7], *args)
    b, acc_b, _, _ = fa.engine.run(7, S0[7:], *args)
    np.testing.assert_array_equal(np.vstack([a, b]), s_fa)
    np.testing.assert_array_equal(np.vstack([acc_a, acc_b]), acc_fa)
