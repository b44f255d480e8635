"""The bench runs end to end (speed itself is reported by `fte bench`, not asserted here)."""

from fte_casadi.sim.bench import bench


def test_bench_smoke(lqr_designs):
    out = bench(lqr_designs["manipulator"], paths=4, baseline_paths=1, horizon=0.5)
    assert out["engine"]["steps"] == 500 and out["engine"]["compiled"]
    assert out["max_abs_diff_engine_vs_sdeint"] < 1e-9
    for key in ("speedup_vs_sdeint", "speedup_vs_python_loop"):
        assert out[key] > 0
