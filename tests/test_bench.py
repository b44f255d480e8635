"""The benchmarks run end to end (speed itself is reported by `fte bench`, not asserted here)."""

import numpy as np
import pytest

from fte_casadi.bench._mc import bench
from fte_casadi.plants import manipulator
from fte_casadi.plants._manipulator import scenario


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
    from fte_casadi.bench import fast_lines

    text = "\n".join(fast_lines(fm, out["engine"]))
    assert "hand-vectorised C loop" in text
    assert ("did not vectorise" in text) == (not all(vec.values()))


def test_layers_do_not_import_the_plants():
    """sim/ and codegen/ sit below the plants: only bench/, _report.py and cli/ may import them."""
    import pathlib
    import re

    root = pathlib.Path(__file__).resolve().parents[1] / "fte_casadi"
    bad = [str(p.relative_to(root)) for sub in ("sim", "codegen", "design", "ts", "model") for p in (root / sub).glob("*.py")
           if re.search(r"^\s*(from \.\.plants|from fte_casadi\.plants|import fte_casadi\.plants)", p.read_text(), re.M)]  # fmt: skip
    assert not bad, bad


def test_leaving_out_the_libm_calls_changes_only_those_lines():
    from fte_casadi.bench._anatomy import _no_libm

    src = "  for (l = 0; l < V; ++l) w3[l] = sin(w1[l]);\n  w4 = w3 * w2;\n  dw[l] = fte_ndtri_tail(p[l]);"
    assert (
        _no_libm(src)
        == "  for (l = 0; l < V; ++l) w3[l] = (w1[l]);\n  w4 = w3 * w2;\n  dw[l] = fte_ndtri_tail(p[l]);"
    )


def test_the_benchmarks_ship_with_the_package():
    """`fte bench` needs no source checkout: the benchmarks are the package's fte_casadi.bench, and
    pyproject's package list takes it into the wheel."""
    import pathlib

    from setuptools import find_packages

    import fte_casadi.bench as bench

    root = pathlib.Path(__file__).resolve().parents[1]
    pkgs = find_packages(str(root), include=["fte_casadi*"])
    assert "fte_casadi.bench" in pkgs and not (root / "benchmarks").exists()
    assert pathlib.Path(bench.__file__).resolve() == root / "fte_casadi" / "bench" / "__init__.py"
    assert callable(bench.run_all) and callable(bench.summary_lines)
    from fte_casadi.cli._bench import BENCH_PARTS

    assert BENCH_PARTS == bench.PARTS


def test_bench_refuses_an_unknown_part():
    from click.testing import CliRunner

    from fte_casadi.cli import main

    r = CliRunner().invoke(main, ["bench", "--only", "nope"])
    assert r.exit_code == 2 and "nope" in r.output and "Traceback" not in r.output


def test_summary_of_one_part_only():
    from fte_casadi.bench import summary_lines

    row = {"casadi_us": 1.0, "state_bytes": 8, "const_bytes": 16, "c_ns": 2.0, "hand_ns": 4.0, "ratio": 0.5}
    lines = summary_lines({"c_step": {"manipulator": row}})
    assert lines[0].startswith("generated C step") and "manipulator" in lines[1] and len(lines) == 2


@pytest.mark.slow
def test_the_report_without_the_benchmarks_keeps_its_sizes(real_designs, monkeypatch, tmp_path):
    """`fte reproduce` where the C step's timings cannot be measured: the C table keeps the sizes and says why."""
    import pytest

    import fte_casadi.bench
    from fte_casadi._report import _c_section
    from fte_casadi.codegen import find_compiler, memory_report
    from fte_casadi.errors import MissingDependencyError

    if find_compiler() is None:
        pytest.skip("no C compiler")

    def missing():
        raise MissingDependencyError("no hand-written loop (test)")

    monkeypatch.setattr(fte_casadi.bench, "bench_c_step", lambda *a, **k: missing())
    d = real_designs["three-tank"]
    lines, info = _c_section(d, tmp_path / "c")
    row = next(ln for ln in lines if ln.startswith("| n/a ns | n/a ns | n/a |"))
    mem = memory_report(d, sample_time=info["ts"])
    assert f"{mem['state_bytes']} B" in row and f"{mem['const_bytes']} B" in row
    assert "(timings: not measured (no hand-written loop (test)).)" in lines
    assert info["check"]["ok"] and info["max_diff"] < 1e-9 and info["bench"]["casadi_us"] is None


def test_the_0_1_design_is_a_baseline_outside_the_wheel_that_fte_bench_runs_from_a_checkout(monkeypatch):
    """The 0.1 formulation is not in the package (nor its wheel): it lives in baselines/, and `fte bench` loads it
    from a checkout; where it is not there (a wheel), the design part is measured and the baseline said not run."""
    import pathlib

    from setuptools import find_packages

    from fte_casadi.bench import _design, summary_lines
    from fte_casadi.plants import manipulator
    from fte_casadi.ts import derive

    root = pathlib.Path(__file__).resolve().parents[1]
    assert not any("baselines" in p for p in find_packages(str(root), include=["fte_casadi*"]))
    assert (
        not list((root / "fte_casadi").rglob("*design_01*"))
        and (root / "baselines" / "design_01.py").is_file()
    )
    assert _design.design_01_baseline() is not None  # from this checkout
    assert _design.design_01_baseline(root / "baselines" / "absent.py") is None
    monkeypatch.setattr(_design, "design_01_baseline", lambda: None)  # as from a wheel
    out = _design.bench_design(derive(manipulator(), fidelity_samples=100), sample_time=1e-3, repeats=1)
    assert out["CLARABEL"]["certified"] and out["design_0.1"] == {"not_run": _design.NOT_RUN_01}
    assert "speedup_vs_0.1" not in out
    line = summary_lines({"design": {"manipulator": out}})[1]
    assert "design_0.1: not run (source checkout only)" in line and "faster than 0.1" not in line


@pytest.mark.slow
def test_the_c_step_bench_runs_a_gate_that_remembers():
    """`fte reproduce`'s C section times the committed manipulator design, whose gate holds latches and memories
    after z (nz > nbar): the CasADi step is called with the whole state (it was called with z alone and raised)."""
    from pathlib import Path

    from fte_casadi.bench import bench_c_step
    from fte_casadi.codegen import find_compiler
    from fte_casadi.design import Design

    d = Design.load(Path(__file__).resolve().parents[1] / "generated" / "manipulator" / "design.json")
    assert d.remembers and d.nz > d.nbar
    b = bench_c_step(d, iters=200, reps=1)
    assert b["casadi_us"] > 0
    if find_compiler() is not None:
        assert b["c_ns"] > 0 and b["sizeof_state"] >= 8 * d.nz


@pytest.mark.slow
def test_the_diffusion_scales_each_condition_allows_grow_with_its_freedom():
    """`fte bench --diffusion PLANT`: the largest diffusion scale each condition allows (bisection to 2 %); a
    condition with more freedom allows at least as much (the design's certificate first, the frozen rules last)."""
    import json
    from pathlib import Path

    from click.testing import CliRunner

    from fte_casadi.cli import main

    plant = str(Path(__file__).parent / "plant_duffing_noisy.py") + ":duffing"
    r = CliRunner().invoke(main, ["bench", "--diffusion", plant, "--at", '{"sigma": 0.5}'])
    assert r.exit_code == 0, r.output
    rows = json.loads(r.stdout.strip().splitlines()[-1])
    assert rows["params"]["sigma"] == 0.5
    s = {
        k: float(v) for k, v in rows.items() if k not in ("params", "seconds")
    }  # "inf" is JSON's text for it
    slack = 1.03  # two bisections to 2 % each
    assert 0 < s["design (45)-(46)"] <= slack * s["design (45)-(46) or (29)"]
    assert s["(46) at step 3's X"] <= slack * s["(29) at P = c X^-1"] <= slack**2 * s["(29), P free"]
    assert s["(29), P free"] <= slack * s["mean-square stability, block-diagonal V"]
    assert s["(29) at the design's gains"] <= slack * s["one full V at the design's gains"]
    assert (
        s["one full V at the design's gains"] <= slack * s["each frozen rule, exactly, at the design's gains"]
    )
    bad = CliRunner().invoke(main, ["bench", "--diffusion", plant, "--at", "[1]"])
    assert bad.exit_code == 2 and "give a JSON object of numbers" in bad.output


def test_the_bound_weights_give_one_json_line_per_weight_and_refuse_what_is_not_one():
    """`fte bench --bound-weights PLANT --weights ...`: a design and a short Monte Carlo per weight, one JSON line
    each, in the order given; a weight of 0 leaves the bound out of the objective."""
    import json

    from click.testing import CliRunner

    from fte_casadi.cli import main

    r = CliRunner().invoke(
        main, ["bench", "--bound-weights", "three-tank", "--weights", "0,1", "--paths", "2"]
    )
    assert r.exit_code == 0, r.output
    rows = [json.loads(line) for line in r.stdout.strip().splitlines()]
    assert [row["weight"] for row in rows] == [0.0, 1.0]
    assert rows[0]["bound_objective"] == [None, None] and rows[1]["bound_objective"][1] is not None
    assert all(len(row["ftc"]) == 1 and row["bound"] > 0 for row in rows)
    for args, why in ((["--weights", "1,-2"], "give weights >= 0"), ([], "needs the weights")):
        bad = CliRunner().invoke(main, ["bench", "--bound-weights", "three-tank", *args])
        assert bad.exit_code == 2 and why in bad.output
    bad = CliRunner().invoke(main, ["bench", "--weights", "1"])
    assert bad.exit_code == 2 and "go with --diffusion PLANT or --bound-weights PLANT" in bad.output
