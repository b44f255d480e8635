"""Monte Carlo engine: Euler-Maruyama statistics, equality with a reference loop, faults, errors."""

import dataclasses

import casadi as ca
import numpy as np
import pytest

from fte_casadi.bench._perpath import monte_carlo
from fte_casadi.errors import ParameterError, SimulationError
from fte_casadi.plants import SCENARIOS
from fte_casadi.sim import LossOfEffectiveness, Scenario, Stuck, UniformNoise, simulate
from fte_casadi.sim import _rng as frng
from fte_casadi.sim._engine import auto_chunk, closed_loop_sample
from fte_casadi.sim._scenario import fault_schedule

GBM_A, GBM_B = 0.5, 0.8  # dX = a X dt + b X dW


def _gbm_sample(dt):
    x = ca.SX.sym("x")
    w = ca.SX.sym("w")
    fp = ca.SX.sym("fp", 0)
    return ca.Function("gbm", [x, w, fp], [x + GBM_A * x * dt + GBM_B * x * w, x])


def _filler(dW: np.ndarray):
    """``fill(W, k0)`` for the engine: increments dW (paths, steps), zeros past the end (padding)."""
    n = dW.shape[1]

    def fill(W, k0):
        W[:, :, 0] = 0.0
        take = dW[:, k0 : min(k0 + W.shape[1], n)]
        W[:, : take.shape[1], 0] = take

    return fill


@pytest.mark.slow
def test_em_reproduces_gbm_mean_and_variance():
    rng = np.random.default_rng(12345)
    paths, T, dt = 20000, 1.0, 1e-2
    n = int(T / dt)
    dW = np.sqrt(dt) * rng.standard_normal((paths, n))
    rec, compiled = monte_carlo(
        _gbm_sample(dt), np.ones((paths, 1)), np.zeros((0, n)), n, 1, _filler(dW), dt=dt
    )
    assert compiled and rec.shape == (paths, n + 1, 1)
    xT = rec[:, n, 0]
    mean_exact = np.exp(GBM_A * T)
    var_exact = np.exp(2 * GBM_A * T) * (np.exp(GBM_B**2 * T) - 1)
    se_mean = np.sqrt(var_exact / paths)
    # EM's own bias on the mean is (1 + a dt)^n vs e^{aT}: ~0.4 % here, below 3 standard errors
    assert abs(xT.mean() - mean_exact) < 3 * se_mean
    assert abs(xT.var() / var_exact - 1) < 0.08
    # and exactly the EM recursion: product of (1 + a dt + b dW)
    np.testing.assert_allclose(xT, np.prod(1 + GBM_A * dt + GBM_B * dW, axis=1), rtol=1e-12)


@pytest.mark.slow
def test_em_strong_order_half():
    rng = np.random.default_rng(7)
    paths, T, kmax = 4000, 1.0, 10
    fine = np.sqrt(T / 2**kmax) * rng.standard_normal((paths, 2**kmax))
    WT = fine.sum(axis=1)
    exact = np.exp((GBM_A - GBM_B**2 / 2) * T + GBM_B * WT)
    dts, errs = [], []
    for k in (4, 5, 6, 7, 8):
        n = 2**k
        dt = T / n
        dW = fine.reshape(paths, n, -1).sum(axis=2)

        rec, _ = monte_carlo(_gbm_sample(dt), np.ones((paths, 1)), np.zeros((0, n)), n, 1, _filler(dW), dt=dt)
        dts.append(dt)
        errs.append(np.mean(np.abs(rec[:, n, 0] - exact)))
    slope = np.polyfit(np.log(dts), np.log(errs), 1)[0]
    assert 0.35 <= slope <= 0.75, (slope, errs)


def _short_manip(T=1.0):
    return Scenario(
        name="short",
        T=1.0,
        dt=1e-3,
        faults=(LossOfEffectiveness("fa", 0.4, 0.25, 0.5), Stuck("fs", 0.7, 0.9)),
        unknown_input=UniformNoise(0.1),
        x0=(0.1, 0.05, 0.02, 0.03),
        x0_noise=0.005,
    ).until(T)


def test_engine_equals_reference_loop(plants, lqr_designs):
    """Vectorised engine == the uninterpreted sample Function stepped by hand with the same noise."""
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = _short_manip(0.3)
    sc = Scenario(
        name="s",
        T=1.0,
        dt=1e-3,
        faults=sc.faults[:1] + (Stuck("fs", 0.6, 0.8),),
        unknown_input=sc.unknown_input,
        x0=sc.x0,
        x0_noise=sc.x0_noise,
    )
    res = simulate(design, plant, sc, paths=3, seed=5, progress=False, record_every=1)
    n = 1000
    t = np.arange(n + 1) * 1e-3
    sched = fault_schedule(
        sc,
        plant.fault_names,
        plant.fault_kinds,
        design.local_models[0].B,
        design.local_models[0].Bf,
        plant.Df,
        plant.input_names,
        t,
        1e-3,
    )
    fn, lay = closed_loop_sample(design, plant, 1e-3, sched)
    FP = sched.stacked()
    q = 2  # path 2 of seed 5: its numbers from the numpy twin of the engine's generator
    x0 = np.asarray(sc.x0) + sc.x0_noise * frng.x0_normals(5, [q], 4)[0]
    nn, uu = frng.step_numbers(5, [q], 0, n + 1, 1)
    dW = np.sqrt(1e-3) * nn[0]
    d = 0.1 * uu[0]
    s = np.zeros(lay.ns)
    z0 = np.concatenate([sc.x0, np.zeros(4)]) - design.H @ (plant.C @ x0)
    for r in range(3):
        s[r * lay.run_state : r * lay.run_state + 4] = x0
        s[r * lay.run_state + 4 : r * lay.run_state + 12] = z0
    recs = []
    for k in range(n + 1):
        nxt, rec = fn(s, np.concatenate([[dW[k]], d[k]]), FP[:, k])
        recs.append(np.asarray(rec).ravel())
        s = np.asarray(nxt).ravel()
    recs = np.array(recs)
    got = np.concatenate(
        [
            res.free.x[q],
            res.free.xbarhat[q],
            res.free.f[q],
            res.free.u[q],
            res.free.y[q],
            res.free.yc[q],
            res.free.ucomp[q],
        ],
        axis=1,
    )
    np.testing.assert_allclose(got, recs[:, : lay.run_rec], rtol=0, atol=1e-10)
    got_ftc = res.ftc.x[q]
    o = 2 * lay.run_rec
    np.testing.assert_allclose(got_ftc, recs[:, o : o + 4], rtol=0, atol=1e-10)


@pytest.fixture(scope="module")
def short_result(plants, lqr_designs):
    return simulate(
        lqr_designs["manipulator"], plants["manipulator"], _short_manip(), paths=4, seed=3, progress=False
    )


def test_fault_semantics(short_result):
    r = short_result
    t = r.t
    on = (t >= 0.25 - 1e-12) & (t < 0.5 - 1e-12)
    nf = r.no_ftc
    # loss of effectiveness: fa = -0.4 u inside the window, 0 outside (B = Bf for the manipulator)
    np.testing.assert_allclose(nf.f[:, on, 0], -0.4 * nf.u[:, on, 0], rtol=1e-12)
    assert np.all(nf.f[:, ~on, 0] == 0.0)
    # stuck: y1 frozen at its reading at the first sample of the window, t = 0.7
    st = (t >= 0.7 - 1e-12) & (t < 0.9 - 1e-12)
    k0 = np.flatnonzero(st)[0]
    y1 = nf.y[:, st, 0]
    np.testing.assert_allclose(y1, np.repeat(nf.x[:, k0 : k0 + 1, 0], st.sum(), axis=1), rtol=0, atol=1e-14)
    assert np.all(nf.f[:, k0, 1] == 0.0)
    assert np.all(np.abs(nf.f[:, ~st, 1]) == 0.0)
    # the free run never sees a fault, and all three runs share x0
    assert np.all(r.free.f == 0.0)
    np.testing.assert_array_equal(r.free.x[:, 0], r.ftc.x[:, 0])
    # the paths differ from each other (independent noise)
    assert np.std(r.free.x[:, -1, 0]) > 0


def test_same_noise_any_block_size(plants, lqr_designs):
    """Path i's trajectory does not depend on the recording stride nor on the number of paths."""
    sc = _short_manip(0.2)
    a = simulate(
        lqr_designs["manipulator"], plants["manipulator"], sc, paths=2, seed=9, progress=False, record_every=1
    )
    b = simulate(
        lqr_designs["manipulator"], plants["manipulator"], sc, paths=3, seed=9, progress=False, record_every=5
    )
    np.testing.assert_allclose(a.ftc.x[:, ::5], b.ftc.x[:2], rtol=0, atol=1e-12)


def test_settings_refused(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = _short_manip(0.1)
    ts_max = design.checks["ts_max"]
    with pytest.raises(SimulationError, match="ts_max"):
        simulate(design, plant, sc, paths=1, seed=0, dt=ts_max * 1.01, progress=False)
    with pytest.raises(ParameterError, match="paths"):
        simulate(design, plant, sc, paths=0, seed=0, progress=False)
    with pytest.raises(SimulationError, match="positive"):
        simulate(design, plant, sc, paths=1, seed=0, dt=-1e-3, progress=False)
    with pytest.raises(ParameterError, match="seed"):
        simulate(design, plant, sc, paths=1, seed=-1, progress=False)
    with pytest.raises(SimulationError, match="does not fit"):
        simulate(lqr_designs["three-tank"], plant, sc, paths=1, seed=0, progress=False)
    with pytest.raises(ParameterError):
        Scenario(name="bad", T=1.0, dt=-0.1)
    with pytest.raises(ParameterError, match="loss"):
        LossOfEffectiveness("fa", 1.5, 0.0, 1.0)


def test_divergence_names_path_and_time(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = Scenario(name="blowup", T=0.5, dt=1e-3, x0=(0.1, 0.05, 0.02, 0.03), divergence_bound=0.5)
    with pytest.raises(SimulationError, match=r"path \d+ diverged at t = "):
        simulate(design, plant, sc, paths=2, seed=0, progress=False)


def test_default_dt_lowered_below_ts_max(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = Scenario(name="coarse", T=0.1, dt=0.05, x0=(0.1, 0.05, 0.02, 0.03))
    res = simulate(design, plant, sc, paths=1, seed=0, progress=False)
    assert res.dt <= design.checks["ts_max"] / 2
    assert res.notes and "ts_max" in res.notes[0]


def test_builtin_scenarios():
    m, t = SCENARIOS["manipulator"](), SCENARIOS["three-tank"]()
    assert (m.T, m.dt, m.paths) == (10.0, 1e-3, 5)
    assert m.windows("fa") == [(2.5, 5.0)] and m.windows("fs") == [(7.0, 10.0)]
    assert (t.T, t.paths) == (600.0, 10) and t.windows("fa") == [(200.0, 400.0)]
    assert Scenario.from_dict(m.to_dict()) == m


@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_vectorised_engine_equals_the_per_path_engine(plants, real_designs, name):
    """Issue #11: the same trajectories as the per-path engine (benchmarks/perpath.py: compiled blocks mapped over paths)
    when both get the same random numbers (the numpy twin of the generator the C draws from): bit for
    bit, since the lane engine rounds every operation as CasADi's C does (no FMA contraction)."""
    from fte_casadi.sim._engine import SCALES, Prepared, resolve_dt

    plant, design = plants[name], real_designs[name]
    sc = SCENARIOS[name]()
    sc = dataclasses.replace(sc, faults=tuple(dataclasses.replace(f, start=f.start / 5, stop=f.stop / 5)
                                              for f in sc.faults))  # fmt: skip
    sc = sc.until(2.0 if name == "manipulator" else 60.0)  # covers the first fault window
    res = simulate(design, plant, sc, paths=3, seed=11, progress=False, record_all=True, record_every=1)
    dt, nsteps, _ = resolve_dt(design, sc, None)
    prep = Prepared(design, plant, sc, dt, nsteps, dict(SCALES))
    paths = np.arange(3)
    nn, uu = frng.step_numbers(11, paths, 0, nsteps + 1, plant.ld)
    amp = sc.unknown_input.amplitude

    def fill(W, k0):
        L = W.shape[1]
        k1 = min(k0 + L, nsteps + 1)
        W[:] = 0.0
        W[:, : k1 - k0, 0] = np.sqrt(dt) * nn[:, k0:k1]
        W[:, : k1 - k0, 1:] = amp * uu[:, k0:k1]

    sched = plant_schedule_for(design, plant, sc, dt, nsteps)
    sample, lay = closed_loop_sample(design, plant, dt, sched)
    rec, _ = monte_carlo(
        sample.expand(),
        prep.initial_states(paths, 11)[:, : prep.lay.ns],
        sched.stacked(),
        nsteps,
        1,
        fill,
        dt=dt,
    )
    got = np.concatenate([getattr(res, run).__dict__[k] for run in ("free", "no_ftc", "ftc")
                          for k in ("x", "xbarhat", "f", "u", "y", "yc", "ucomp")], axis=2)  # fmt: skip
    assert np.all(np.isfinite(rec)) and np.abs(res.ftc.f).max() > 0  # a fault acted
    np.testing.assert_array_equal(got, rec)


def plant_schedule_for(design, plant, sc, dt, nsteps):
    from fte_casadi.sim._engine import plant_schedule

    return plant_schedule(design, plant, sc, np.arange(nsteps + 2000) * dt, dt)


def test_metrics_do_not_depend_on_chunks_or_threads(plants, lqr_designs):
    """Issue #11: path i's numbers depend on (seed, i) only and the sums are combined exactly."""
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = _short_manip(0.5)
    a = simulate(design, plant, sc, paths=37, seed=4, progress=False, chunk=256, threads=2).metrics
    b = simulate(design, plant, sc, paths=37, seed=4, progress=False, chunk=5, threads=1).metrics
    c = simulate(design, plant, sc, paths=37, seed=4, progress=False, threads=3).metrics  # default chunks
    for m in (a, b, c):
        m.pop("wall_s")
    assert a == b == c
    assert auto_chunk(37, 3) == 8 and auto_chunk(1000, 2) == 128 and auto_chunk(10**6, 2) == 256


def test_streamed_metrics_equal_the_reference_from_arrays(plants, real_designs, tmp_path):
    """The metrics reduced in the compiled loop equal those recomputed from every recorded sample."""
    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim import load_result, metrics_from_arrays, save_result

    for name in ("manipulator", "three-tank"):
        sc = SCENARIOS[name]()
        sc = sc.until(sc.T if name == "manipulator" else 300.0)
        res = simulate(real_designs[name], plants[name], sc, paths=6, seed=2, progress=False, record_all=True,
                       record_every=1)  # fmt: skip
        save_result(res, tmp_path / f"{name}.npz")  # recompute from the saved per-path arrays
        res = load_result(tmp_path / f"{name}.npz")
        ref, got = metrics_from_arrays(res), res.metrics
        for key in ("state_rms_error", "fault_rel_rms_error", "fault_rel_rms_error_settled", "false_alarm_rel_rms",
                    "false_alarm_peak", "input_saturation", "outside_c_range_per_output"):  # fmt: skip
            assert [v is None for v in got[key]] == [v is None for v in ref[key]]
            np.testing.assert_allclose([v for v in got[key] if v is not None], [v for v in ref[key] if v is not None],
                                       rtol=1e-12, atol=1e-15)  # fmt: skip
        for key in ("ftc_true_ratio", "ftc_compensated_ratio", "outside_region", "transient", "settle_after",
                    "outside_c_range", "outside_c_range_paths"):  # fmt: skip
            assert got[key] == pytest.approx(ref[key], rel=1e-12), key
        assert got["state_range"] == ref["state_range"] and got["region"] == ref["region"]
        assert got["c_accepted_range"] == ref["c_accepted_range"] and got["outside_c_range_first"] == ref[
            "outside_c_range_first"]  # fmt: skip
        assert len(got["windows"]) == len(sc.faults) == len(ref["windows"])
        for w, v in zip(got["windows"], ref["windows"]):
            assert (w["fault"], w["start"], w["stop"]) == (v["fault"], v["start"], v["stop"])
            for k in ("fault_rel_rms_error", "fault_rel_rms_error_settled", "ftc_true_ratio", "ftc_compensated_ratio",
                      "settling_time", "release_time", "detection_delay", "missed_detections"):  # fmt: skip
                assert (w[k] is None and v[k] is None) or w[k] == pytest.approx(v[k], rel=1e-12)
            np.testing.assert_allclose(w["input_saturation"], v["input_saturation"], rtol=1e-12, atol=0)
            assert w["fault_peak"] == pytest.approx(v["fault_peak"], rel=1e-12)
            np.testing.assert_allclose(
                w["sensor_fault_peak_per_output"], v["sensor_fault_peak_per_output"], rtol=1e-12
            )
            _same_after_window(w["after_window"], v["after_window"])
        if name == "manipulator":  # fa [2.5, 5) has a span after it, up to fs at 7; fs none before T = 10
            assert [w["after_window"] is not None for w in got["windows"]] == [True, False]
            assert (
                got["windows"][0]["after_window"]["start"],
                got["windows"][0]["after_window"]["stop"],
            ) == (5.0, 7.0)


def test_the_span_after_a_window_holds_no_fault():
    """``after_window``'s span: from the window's end to the next window's start (or the horizon); empty where
    another window holds the end (overlapping windows) or starts at it."""
    from fte_casadi.sim._masks import after_mask, after_span

    wins = [("fa", 2.0, 5.0), ("fs", 7.0, 10.0)]
    assert after_span(wins, 0, 12.0) == (5.0, 7.0) and after_span(wins, 1, 12.0) == (10.0, 12.0)
    overlap = [("fa", 2.0, 6.0), ("fs", 4.0, 8.0)]  # fs holds fa's end: no fault-free span after fa
    assert after_span(overlap, 0, 12.0) == (6.0, 6.0) and after_span(overlap, 1, 12.0) == (8.0, 12.0)
    assert after_span([("fa", 2.0, 5.0), ("fs", 5.0, 8.0)], 0, 12.0) == (5.0, 5.0)
    t = np.arange(0.0, 12.0, 0.5)
    assert not after_mask(t, overlap, 0, 12.0).any() and after_mask(t, overlap, 1, 12.0).sum() == 8


def _same_after_window(a: dict | None, b: dict | None) -> None:
    """The streamed ``after_window`` figures of a window equal the reference's."""
    assert (a is None) == (b is None)
    if a is None:
        return
    assert (a["start"], a["stop"]) == (b["start"], b["stop"])
    assert a["ftc_true_ratio"] == pytest.approx(b["ftc_true_ratio"], rel=1e-12)
    assert a["ftc_true_ratio_with_window"] == pytest.approx(b["ftc_true_ratio_with_window"], rel=1e-12)
    np.testing.assert_allclose(a["ftc_true_ratio_with_window_interval"], b["ftc_true_ratio_with_window_interval"],
                               rtol=1e-9)  # fmt: skip
    for key in ("ftc_true_ratio_per_output", "ftc_compensation_rms"):
        np.testing.assert_allclose(a[key], b[key], rtol=1e-12, atol=0)
    for run in ("ftc", "no_ftc"):
        np.testing.assert_allclose(
            a["ftc_true_rms_per_output"][run], b["ftc_true_rms_per_output"][run], rtol=1e-12
        )
    np.testing.assert_allclose(a["ftc_true_ratio_interval"], b["ftc_true_ratio_interval"], rtol=1e-9)
    np.testing.assert_allclose(a["ftc_true_ratio_per_output_interval"], b["ftc_true_ratio_per_output_interval"],
                               rtol=1e-9)  # fmt: skip


def test_memory_does_not_grow_with_paths(plants, lqr_designs):
    """Only the example paths keep trajectories: 50 or 500 paths retain the same arrays."""
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = _short_manip(0.3)
    a = simulate(design, plant, sc, paths=50, seed=1, progress=False)
    b = simulate(design, plant, sc, paths=500, seed=1, progress=False)
    assert a.recorded_paths == b.recorded_paths == sc.paths
    assert a.ftc.x.nbytes == b.ftc.x.nbytes and b.metrics["paths"] == 500
    np.testing.assert_array_equal(a.ftc.x, b.ftc.x)  # the example paths are the same paths


def test_all_paths_recorded_in_their_chunks_equal_the_example_paths(plants, lqr_designs):
    """With record_all (--save) the chunks record as they run; their first paths are the examples."""
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    sc = _short_manip(0.3)
    kw = dict(paths=21, seed=8, progress=False, record_every=3, threads=2, chunk=8)
    a = simulate(design, plant, sc, record_all=True, **kw)
    b = simulate(design, plant, sc, **kw)
    assert a.recorded_paths == 21 and b.recorded_paths == sc.paths
    np.testing.assert_array_equal(a.ftc.x[: sc.paths], b.ftc.x)
    np.testing.assert_array_equal(a.no_ftc.yc[: sc.paths], b.no_ftc.yc)
    a.metrics.pop("wall_s"), b.metrics.pop("wall_s")
    assert a.metrics == b.metrics
