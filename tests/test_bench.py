"""The benchmarks run end to end (speed itself is reported by `fte bench`, not asserted here)."""

import numpy as np

from benchmarks.mc import bench
from fte_casadi.plants import manipulator
from fte_casadi.plants.manipulator import scenario


def test_monte_carlo_bench_smoke(lqr_designs):
    out = bench(
        lqr_designs["manipulator"],
        manipulator(),
        scenario(),
        paths=16,
        baseline_paths=1,
        horizon=0.5,
        repeats=1,
        fast_repeats=1,
    )
    e = out["engine"]
    assert e["steps"] == 500 and e["flops_per_path_step"] > 100
    assert 0 < e["fraction_of_peak"] < 1
    ops = e["operations_per_path_step"]
    # the manipulator: sin(theta_l) once per run after CasADi's cse
    assert ops["libm_calls_by_function"] == {"sin": 3}
    assert ops["flops"] == ops["flops_closed_loop"] + 40  # 36 for the normal, 4 for the unknown input
    one = e["one_thread"]
    assert one["ns_per_path_step"] > 0 and 0 <= one["libm_share"] < 1
    assert out["per_path_engine"]["path_steps_per_s"] > 0 and out["speedup_vs_per_path"] > 0
    assert out["max_abs_diff_engine_vs_sdeint"] < 1e-9  # the baselines integrate the same SDE
    for key in ("speedup_vs_sdeint", "speedup_vs_python_loop"):
        assert out[key] > 0
    fm = out["fast_mode"]
    assert fm["path_steps_per_s"] > 0 and fm["speedup_vs_exact"] > 0
    h = fm["one_thread_vs_hand_loop"]
    # the hand loop computes the engine's numbers (to rounding); whether GCC vectorised its path loop is the
    # compiler's choice on this CPU (yes with AVX-512 on the development machine, no on an AVX2 Zen 3 with
    # GCC 12): it is reported, and the summary says when the baseline is scalar
    assert max(h["hand_max_rel_diff_final_state"].values()) < 1e-9
    vec = h["hand_path_loop_vectorised"]
    assert set(vec) == {f"{v}_{b}" for v in ("hand", "hand_fast_math") for b in (8, 16, 64)}
    assert all(isinstance(x, bool) for x in vec.values())
    assert h["ratio_fast_vs_hand"] > 0 and h["ratio_exact_vs_hand"] > 0
    # the hand loop built with -ffast-math did not switch this process to flush-to-zero (crtfastmath.o)
    tiny = np.array([2.0e-308])
    assert (tiny / 4.0)[0] > 0.0
    from benchmarks import fast_lines

    text = "\n".join(fast_lines(fm, out["engine"]))
    assert "hand-vectorised C loop" in text
    assert ("did not vectorise" in text) == (not all(vec.values()))


def test_layers_do_not_import_the_plants():
    """sim/ and codegen/ sit below the plants: only benchmarks/, report.py and cli.py may import them."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[1] / "fte_casadi"
    bad = [str(p.relative_to(root)) for sub in ("sim", "codegen", "design", "ts", "model") for p in (root / sub).glob("*.py")
           if re.search(r"^\s*(from \.\.plants|from fte_casadi\.plants|import fte_casadi\.plants)", p.read_text(), re.M)]  # fmt: skip
    assert not bad, bad


def test_leaving_out_the_libm_calls_changes_only_those_lines():
    from benchmarks.anatomy import _no_libm

    src = "  for (l = 0; l < V; ++l) w3[l] = sin(w1[l]);\n  w4 = w3 * w2;\n  dw[l] = fte_ndtri_tail(p[l]);"
    assert (
        _no_libm(src)
        == "  for (l = 0; l < V; ++l) w3[l] = (w1[l]);\n  w4 = w3 * w2;\n  dw[l] = fte_ndtri_tail(p[l]);"
    )


def test_bench_finds_the_checkouts_benchmarks(monkeypatch):
    """`fte bench` loads benchmarks/ from the checkout beside fte_casadi/ when it is not imported yet."""
    import pathlib
    import sys

    from fte_casadi.checkout import load_benchmarks

    monkeypatch.delitem(sys.modules, "benchmarks", raising=False)
    mod = load_benchmarks()
    root = pathlib.Path(__file__).resolve().parents[1]
    assert pathlib.Path(mod.__file__).resolve() == root / "benchmarks" / "__init__.py"
    assert callable(mod.run_all) and callable(mod.summary_lines)


def test_bench_without_the_benchmarks_says_where_they_are(monkeypatch, tmp_path):
    """An installed wheel holds fte_casadi only: `fte bench` says so, exit status 2, no traceback."""
    import sys

    from click.testing import CliRunner

    from fte_casadi import checkout
    from fte_casadi.cli import main

    (tmp_path / "fte_casadi").mkdir()
    monkeypatch.delitem(sys.modules, "benchmarks", raising=False)
    monkeypatch.setattr(checkout, "__file__", str(tmp_path / "fte_casadi" / "checkout.py"))
    r = CliRunner().invoke(main, ["bench"])
    assert r.exit_code == 2, r.output
    assert "source repository" in r.output and "checkout" in r.output and "Traceback" not in r.output


def test_the_wheel_holds_no_benchmarks_nor_history():
    """pyproject's package list: fte_casadi only; the baselines (0.1 design, per-path engine) live in benchmarks/."""
    import pathlib

    from setuptools import find_packages

    root = pathlib.Path(__file__).resolve().parents[1]
    pkgs = find_packages(str(root), include=["fte_casadi*"])
    assert "fte_casadi" in pkgs and not any(p.startswith("benchmarks") for p in pkgs)
    files = {p.name for p in (root / "fte_casadi").rglob("*.py")}
    assert not files & {"legacy.py", "perpath.py", "mc.py", "cstep.py"}
    assert not any("legacy" in p.read_text() for p in (root / "fte_casadi").rglob("*.py"))


def test_the_report_without_the_benchmarks_keeps_its_sizes(real_designs, monkeypatch, tmp_path):
    """`fte reproduce` from a wheel: the C table keeps the sizes and says where the timings come from."""
    import pytest

    from fte_casadi import checkout
    from fte_casadi.codegen import find_compiler
    from fte_casadi.codegen.generate import memory_report
    from fte_casadi.errors import MissingDependencyError
    from fte_casadi.report import _c_section

    if find_compiler() is None:
        pytest.skip("no C compiler")

    def missing():
        raise MissingDependencyError("no benchmarks (test)")

    monkeypatch.setattr(checkout, "load_benchmarks", missing)
    d = real_designs["three-tank"]
    lines, info = _c_section(d, tmp_path / "c")
    row = next(ln for ln in lines if ln.startswith("| n/a ns | n/a ns | n/a |"))
    mem = memory_report(d, sample_time=info["ts"])
    assert f"{mem['state_bytes']} B" in row and f"{mem['const_bytes']} B" in row
    assert "(timings: run from a source checkout.)" in lines
    assert info["max_diff"] < 1e-9 and info["bench"]["casadi_us"] is None
