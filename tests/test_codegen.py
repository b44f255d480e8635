"""Generated C: compiled with the strict flags, loaded back with ctypes, compared with CasADi.

The way CasADi tests its own code generation: the in-process Function is the reference, the
compiled code must reproduce it per step (double: C_DOUBLE absolute on O(1) values; float:
C_FLOAT_REL relative to the size of each output vector) and along a closed-loop run of each
built-in nonlinear plant.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
from pathlib import Path

import numpy as np
import pytest
from tolerances import C_DOUBLE, C_FLOAT_REL

from fte_casadi._rounding import series_floor
from fte_casadi.codegen import CStep, closed_loop_compare
from fte_casadi.codegen import _build as build
from fte_casadi.codegen._generate import c_name, default_sample_time, generate_c, output_files
from fte_casadi.errors import CodegenError, DesignFileError, ParameterError
from fte_casadi.plants import load_plant
from fte_casadi.step import step_function

PLANTS = ("manipulator", "three-tank")
REPO = Path(__file__).resolve().parents[1]
FORBIDDEN = re.compile(
    r"\b(malloc|calloc|realloc|free|printf|fprintf|sprintf|puts|fopen|fwrite|fread)\b|stdio\.h"
)

needs_cc = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")


@pytest.fixture(scope="module")
def designs(real_designs):
    """The conditioned LMI designs of the built-in plants (shared with the other test modules)."""
    return real_designs


@pytest.fixture(scope="module")
def libs(designs, tmp_path_factory):
    """Shared libraries of every plant in double and float, compiled under the strict flags."""
    if build.find_compiler() is None:
        pytest.skip("no C compiler (cc, gcc, clang) on PATH")
    out = {}
    for plant, d in designs.items():
        for real in ("double", "float"):
            src = tmp_path_factory.mktemp(f"{c_name(plant)}_{real}")
            generate_c(d, src, real=real)
            out[plant, real] = (src, build.compile_shared(src, src / "libstep.so"))
    return out


def _samples(design, k: int, seed: int):
    rng = np.random.default_rng(seed)
    nbar, p = int(design.dims.nbar), int(design.dims.p)
    y0 = np.asarray(design.C) @ (np.zeros(design.dims.n) if design.x_ref is None else design.x_ref)
    for _ in range(k):
        yield rng.normal(scale=0.5, size=nbar), y0 + rng.normal(scale=0.5, size=p)


@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
def test_double_step_matches_casadi(plant, designs, libs):
    d = designs[plant]
    fn = step_function(d, default_sample_time(d))
    c = CStep(libs[plant, "double"][1], d, "double")
    worst = 0.0
    for z, y in _samples(d, 200, seed=1):
        zn, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z, y))
        c.init(z)
        rc, uc, xbc, ycc = c.step(y)
        assert rc == 0
        for a, b in ((c.z, zn), (uc, u), (xbc, xb), (ycc, yc)):
            worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))))
    assert worst <= C_DOUBLE


@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
def test_float_step_matches_casadi(plant, designs, libs):
    """Float code from the same (z, y): each output within C_FLOAT_REL of its vector's size."""
    d = designs[plant]
    fn = step_function(d, default_sample_time(d))
    c = CStep(libs[plant, "float"][1], d, "float")
    worst = 0.0
    for z, y in _samples(d, 200, seed=2):
        z32, y32 = np.float32(z).astype(float), np.float32(y).astype(float)
        zn, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z32, y32))
        c.init(z32)
        rc, uc, xbc, ycc = c.step(y32)
        assert rc == 0
        for a, b in ((c.z, zn), (uc, u), (xbc, xb), (ycc, yc)):
            worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))))
    assert worst <= C_FLOAT_REL
    assert worst > 0.0  # it is float arithmetic: a zero difference would mean double code was loaded


def _fault(plant):
    if plant == "manipulator":  # 40 % loss of actuator effectiveness after 0.5 s
        return lambda t, u: np.array([-0.4 * u[0] if t >= 0.5 else 0.0, 0.0])
    return lambda t, u: np.array([-10.0 if t >= 5.0 else 0.0])  # pump 2 delivers 10 cm^3/s less


@pytest.mark.slow
@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
def test_closed_loop_trajectory_matches_casadi(plant, designs, libs):
    d = designs[plant]
    sample_time = default_sample_time(d)
    steps = int(round((1.5 if plant == "manipulator" else 20.0) / sample_time))
    c = CStep(libs[plant, "double"][1], d, "double")
    err, traj = closed_loop_compare(
        d, c, sample_time, min(steps, 2000), plant=load_plant(plant), fault=_fault(plant)
    )
    scale = max(1.0, float(np.max(np.abs(traj["y"]))), float(np.max(np.abs(traj["u"]))))
    assert max(err.values()) <= C_DOUBLE * scale, err  # same operations in the same order: round-off only
    assert np.all(np.isfinite(traj["u"]))
    assert np.max(np.abs(traj["fhat"][-1])) > 0  # the fault estimate moved: the loop was exercised


@pytest.mark.slow
@needs_cc
def test_saturating_closed_loop_matches_casadi(designs, libs):
    """Issue #12: the C step clips u into the pumps' limits exactly as the Python step does, over a
    closed loop that does saturate (the observer starts at z = 0, far from the plant)."""
    d = designs["three-tank"]
    lim = np.asarray(d.input_limits)
    assert np.array_equal(lim, [[0.0, 100.0], [0.0, 100.0]])
    sample_time = default_sample_time(d)
    c = CStep(libs["three-tank", "double"][1], d, "double")
    err, traj = closed_loop_compare(
        d, c, sample_time, 2000, plant=load_plant("three-tank"), fault=_fault("three-tank")
    )
    u = traj["u"]
    assert np.all(u >= lim[:, 0]) and np.all(u <= lim[:, 1])
    assert np.any(u == lim[:, 0]) and np.any(u == lim[:, 1])  # both limits were hit
    scale = max(1.0, float(np.max(np.abs(traj["y"]))), float(np.max(np.abs(u))))
    assert max(err.values()) <= C_DOUBLE * scale, err
    header = (libs["three-tank", "double"][0] / "fte_three_tank.h").read_text()
    assert "u is clipped to Q1 in [0, 100], Q2 in [0, 100]" in header


@needs_cc
@pytest.mark.parametrize("real", ["double", "float"])
@pytest.mark.parametrize("bad", [np.nan, np.inf, -np.inf])
def test_non_finite_measurement_refused_state_unchanged(bad, real, designs, libs):
    d = designs["manipulator"]
    c = CStep(libs["manipulator", real][1], d, real)
    z0 = np.arange(1.0, d.nbar + 1) / 10
    c.init(z0)
    before = bytes(c.state)
    y = np.array([0.1, bad, 0.2])
    rc, *_ = c.step(y)
    assert rc != 0
    assert bytes(c.state) == before
    rc, *_ = c.step(np.array([0.1, 0.0, 0.2]))  # a finite y afterwards works and moves the state
    assert rc == 0 and bytes(c.state) != before


@needs_cc
def test_boundary_layer_variant_matches(designs, tmp_path):
    d = designs["manipulator"]
    generate_c(d, tmp_path, boundary_layer=0.05)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "lib.so"), d)
    fn = step_function(d, default_sample_time(d), boundary_layer=0.05)
    for z, y in _samples(d, 50, seed=3):
        c.init(z)
        rc, uc, xbc, _ = c.step(y)
        zn, u, *_ = (np.asarray(v).ravel() for v in fn(z, y))
        assert rc == 0 and np.max(np.abs(c.z - zn)) <= C_DOUBLE * max(1.0, np.max(np.abs(zn)))


def _generated_dirs(libs):
    dirs = [src for src, _ in libs.values()]
    dirs += [REPO / "generated" / sub for sub in ("manipulator", "three_tank")]
    return [d for d in dirs if d.is_dir()]


@needs_cc
def test_no_heap_io_or_mutable_globals(libs):
    checked = 0
    for folder in _generated_dirs(libs):
        for f in sorted(folder.glob("*.[ch]")):
            text = f.read_text()
            code = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
            assert not FORBIDDEN.search(code), f"{f}: {FORBIDDEN.search(code).group(0)}"
            for line in code.splitlines():  # file-scope statics must be const
                if line.startswith("static ") and "(" not in line:
                    assert "const" in line, f"{f}: mutable static {line!r}"
            checked += 1
    assert checked >= 16


@pytest.mark.slow
@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
@pytest.mark.parametrize("real", ["double", "float"])
def test_strict_compile_with_callers_main(plant, real, designs, libs, tmp_path):
    src = libs[plant, real][0]
    name = c_name(plant)
    main = tmp_path / "main.c"
    main.write_text(
        f'#include "fte_{name}.h"\n'
        "int main(void) {\n"
        f"  fte_{name}_state s;\n"
        f"  fte_real y[FTE_{name.upper()}_NY] = {{0}};\n"
        f"  fte_real u[FTE_{name.upper()}_NU];\n"
        "  int k, rc = 0;\n"
        f"  fte_{name}_init(&s, 0);\n"
        # a measurement in the middle of the accepted range (0 is outside the three-tank's)
        f"  for (k = 0; k < FTE_{name.upper()}_NY; ++k) y[k] = (fte_{name}_Y_MIN[k] + fte_{name}_Y_MAX[k]) / 2;\n"
        f"  for (k = 0; k < 10; ++k) rc |= fte_{name}_step(&s, y, u, 0, 0);\n"
        f"  y[0] = (fte_real)(0.0 / (double)(k - k));\n"
        f"  return rc == 0 && fte_{name}_step(&s, y, u, 0, 0) == 1 && FTE_{name.upper()}_TS > 0 ? 0 : 1;\n"
        "}\n"
    )
    exe = build.compile_program(src, main, tmp_path / "prog")
    # exit status 0: ten finite steps returned 0 and the NaN measurement was refused with 1
    assert subprocess.run([str(exe)], timeout=60).returncode == 0


@needs_cc
def test_readme_states_memory_and_sample_time(designs, libs):
    d = designs["three-tank"]
    src = libs["three-tank", "double"][0]
    text = (src / "README.md").read_text()
    assert f"Ts = {default_sample_time(d)!r}" in text
    nbar = int(d.dims.nbar)
    assert f"{2 * nbar * 8} bytes" in text
    assert "numeric literals" in text


# ---- bad inputs: each refused with a clear message, nothing half-written -------------------------


def _listing(folder: Path):
    return sorted(p.name for p in folder.iterdir()) if folder.exists() else None


def test_ts_above_ts_max_refused(designs, tmp_path):
    d = designs["manipulator"]
    ts_max = d.checks["ts_max"]
    out = tmp_path / "out"
    with pytest.raises(ParameterError, match=f"ts_max = {ts_max:.6g}"):
        generate_c(d, out, sample_time=2 * ts_max)
    for bad in (0.0, -1e-3, float("nan")):
        with pytest.raises(ParameterError, match="positive"):
            generate_c(d, out, sample_time=bad)
    assert not out.exists()


def test_bad_real_refused(designs, tmp_path):
    with pytest.raises(ParameterError, match="double"):
        generate_c(designs["manipulator"], tmp_path / "o", real="long double")
    assert not (tmp_path / "o").exists()


@pytest.mark.parametrize(
    "mutate, match",
    [
        (lambda t: t.replace('"H": [\n  [\n   ', '"H": [\n  [\n   NaN, ', 1), "NaN"),
        (lambda t: json.dumps({k: v for k, v in json.loads(t).items() if k != "H"}), "lacks key"),
        (lambda t: t[: len(t) // 2], "truncated"),
    ],
    ids=["nan", "missing-key", "truncated"],
)
def test_bad_design_document_refused(mutate, match, designs, tmp_path):
    text = designs["manipulator"].to_json()
    bad = mutate(text)
    assert bad != text
    path = tmp_path / "design.json"
    path.write_text(bad)
    out = tmp_path / "out"
    with pytest.raises(DesignFileError, match=match):
        generate_c(path, out)
    assert not out.exists()


def test_design_document_path_accepted(designs, tmp_path):
    path = tmp_path / "design.json"
    designs["three-tank"].save(path)
    files = generate_c(path, tmp_path / "out")
    assert [f.name for f in files] == output_files("three-tank")


def test_unwritable_dir_refused(designs, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("not a directory")
    for out in (blocker / "sub", blocker):
        with pytest.raises(CodegenError, match="directory"):
            generate_c(designs["manipulator"], out)
    assert blocker.read_text() == "not a directory"


def test_only_own_files_written_others_kept(designs, tmp_path):
    (tmp_path / "main.c").write_text("/* mine */\n")
    (tmp_path / "notes.txt").write_text("keep")
    generate_c(designs["manipulator"], tmp_path)
    assert _listing(tmp_path) == sorted(output_files("manipulator") + ["main.c", "notes.txt"])
    assert (tmp_path / "main.c").read_text() == "/* mine */\n"


def test_failed_write_leaves_nothing_half_written(designs, tmp_path, monkeypatch):
    generate_c(designs["manipulator"], tmp_path, sample_time=0.001)
    before = {p.name: p.read_bytes() for p in tmp_path.iterdir()}
    real_fsync, calls = os.fsync, []

    def failing_fsync(fd):
        calls.append(fd)
        if len(calls) == 3:
            raise OSError(28, "No space left on device")
        real_fsync(fd)

    monkeypatch.setattr(os, "fsync", failing_fsync)
    with pytest.raises(CodegenError, match="No space left"):
        generate_c(designs["manipulator"], tmp_path, sample_time=0.002)
    assert {p.name: p.read_bytes() for p in tmp_path.iterdir()} == before  # old files intact, no temporaries


def test_default_sample_time(designs):
    """The sample time the design was made for (the scenario's step, which fte simulate runs); without
    one, a tenth of ts_max rounded down to 1-2-5, capped by the scenario's step when one is given."""
    import dataclasses

    from fte_casadi.plants import SCENARIOS

    for plant, d in designs.items():
        sample_time, ts_max = default_sample_time(d), d.checks["ts_max"]
        assert sample_time == d.observer.sample_time == SCENARIOS[plant]().dt < ts_max
        bare = dataclasses.replace(
            d, observer={k: v for k, v in d.observer.to_dict().items() if k != "sample_time"}
        )
        sample_time = default_sample_time(bare)
        assert sample_time <= 0.1 * ts_max and f"{sample_time:e}"[0] in "125"
        assert sample_time == series_floor(0.1 * ts_max)
        step = SCENARIOS[plant]().dt
        assert default_sample_time(bare, step) == min(step, series_floor(0.1 * ts_max))
        assert default_sample_time(bare, 1e-9) == 1e-9  # the cap is the scenario's step given
    d = designs["three-tank"]
    user = dataclasses.replace(
        d, plant="my-tank", observer={k: v for k, v in d.observer.to_dict().items() if k != "sample_time"}
    )
    assert default_sample_time(user) == series_floor(0.1 * user.checks["ts_max"])
    assert 0.04 * user.checks["ts_max"] < default_sample_time(user) <= 0.1 * user.checks["ts_max"]
    motor = dataclasses.replace(d, plant="motor", observer=dict(d.observer.to_dict(), sample_time=1e-3))
    assert default_sample_time(motor) == 1e-3  # the simulated rate, not a tenth of ts_max
    too_slow = dataclasses.replace(
        d, plant="motor", observer=dict(d.observer.to_dict(), sample_time=2 * d.checks["ts_max"])
    )
    assert default_sample_time(too_slow) == series_floor(
        0.1 * d.checks["ts_max"]
    )  # never an unstable default
    assert [series_floor(v) for v in (0.0999, 0.1, 0.35, 7.0, 1.99e-3)] == [0.05, 0.1, 0.2, 5.0, 1e-3]


def test_missing_ts_max_refused(designs, tmp_path):
    import dataclasses

    d = designs["manipulator"]
    bad = dataclasses.replace(d, checks={k: v for k, v in d.checks.items() if k != "ts_max"})
    with pytest.raises(CodegenError, match="ts_max"):
        generate_c(bad, tmp_path / "o")
    assert not (tmp_path / "o").exists()


def test_no_compiler_is_reported(monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    monkeypatch.delenv("CC", raising=False)
    assert build.find_compiler() is None
    with pytest.raises(CodegenError, match="no C compiler"):
        build.compile_shared(tmp_path, tmp_path / "x.so")


@pytest.mark.slow
@needs_cc
def test_bench_measures_and_baseline_agrees(designs):
    """The benchmark runs; its hand-written baseline computes the same step; no mutable globals."""
    from fte_casadi.bench import bench_c_step

    res = bench_c_step(designs["three-tank"], iters=2000, reps=1)
    assert res["c_ns"] > 0 and res["hand_ns"] > 0 and res["casadi_us"] > 0
    assert res["hand_max_diff"] <= 1e-9  # same maths up to summation order, values of O(10)
    assert res["sizeof_state"] == res["state_bytes"]
    if res["objects"] is not None:
        assert res["objects"]["data"] == 0 and res["objects"]["bss"] == 0


@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
def test_init_from_y_starts_as_the_simulation(plant, designs, libs):
    """Issue #21: the C started from its first measurement holds the observer state the Monte Carlo
    engine starts from (z0 = [x0; 0; 0] - H C x0 for each path's x0), and a bad y0 is refused."""
    from fte_casadi.plants import SCENARIOS
    from fte_casadi.sim._engine import Prepared, _scales

    d = designs[plant]
    sc = SCENARIOS[plant]()
    np.testing.assert_array_equal(d.xbar0[: d.dims.n], np.asarray(sc.x0, float))
    prep = Prepared(d, load_plant(plant), sc, sc.dt, 4, _scales(None, sc))
    lay = prep.lay
    start = prep.initial_states(np.arange(3), seed=7)
    c = CStep(libs[plant, "double"][1], d, "double")
    o = 2 * lay.run_state  # the run with tolerant control; all three start alike
    for row in start:
        x0 = row[o : o + lay.n]
        z_sim = row[o + lay.n : o + lay.n + lay.nbar]
        assert np.max(np.abs(x0 - d.xbar0[: lay.n])) > 0  # the path's x0 carries its noise
        assert c.init_from_y(np.asarray(d.C) @ x0) == 0
        np.testing.assert_allclose(c.z, z_sim, rtol=0, atol=1e-12 * max(1.0, np.max(np.abs(z_sim))))
    before = c.z.copy()
    bad = np.asarray(d.C) @ d.xbar0[: lay.n]
    bad[0] = np.nan
    assert c.init_from_y(bad) == 1
    np.testing.assert_array_equal(c.z, before)  # refused: the state is unchanged


@pytest.mark.slow
@needs_cc
@pytest.mark.parametrize("plant", PLANTS)
def test_closed_loop_from_first_measurement_matches_casadi(plant, designs, libs):
    """The start-up window: plant at the nominal x0, both observers started from y0 (C: init_from_y)."""
    d = designs[plant]
    sample_time = default_sample_time(d)
    c = CStep(libs[plant, "double"][1], d, "double")
    steps = min(int(round((1.0 if plant == "manipulator" else 20.0) / sample_time)), 1000)
    err, traj = closed_loop_compare(d, c, sample_time, steps, plant=load_plant(plant), start_from_y=True)
    scale = max(1.0, float(np.max(np.abs(traj["y"]))), float(np.max(np.abs(traj["u"]))))
    assert max(err.values()) <= C_DOUBLE * scale, err
    # started where the plant is, the fault-free estimate stays near zero from the first sample on
    assert np.max(np.abs(traj["fhat"][0])) <= 1e-9 * scale
