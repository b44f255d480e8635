"""`fte codegen --check`: the generated C, fed the measurements of a simulated path, returns what the simulation
applied; where it does not (a difference, a refused measurement), the check fails and says where."""

import dataclasses
import math

import numpy as np
import pytest
from click.testing import CliRunner

import fte_casadi.sim._c_check as replay
from fte_casadi.cli import main
from fte_casadi.codegen import find_compiler, generate_c
from fte_casadi.plants import BUILTIN, SCENARIOS
from fte_casadi.sim import Bias, SimulateOptions, check_c, simulate
from fte_casadi.sim._c_check import first_observer_state
from fte_casadi.sim._result import RUNS
from fte_casadi.sim._start import observer_start

needs_cc = pytest.mark.skipif(find_compiler() is None, reason="no C compiler")


def run(*args):
    r = CliRunner().invoke(main, list(args))
    assert "Traceback" not in (r.output or ""), r.output
    r.text = " ".join((r.output or "").split())
    return r


@pytest.fixture(scope="module")
def manipulator_doc(real_designs, tmp_path_factory):
    f = tmp_path_factory.mktemp("check") / "manipulator.json"
    real_designs["manipulator"].save(f)
    return f


def _check(d, folder, sabotage=None, monkeypatch=None):
    """check_c on the manipulator's scenario; ``sabotage(y, sim)`` changes what the C is fed or compared with."""
    ts = SCENARIOS["manipulator"]().dt
    generate_c(d, folder, sample_time=ts)
    if sabotage is not None:
        original = replay._replay

        def changed(design, cstep, z0, y, sim, **kw):
            y, sim = y.copy(), {k: v.copy() for k, v in sim.items()}
            sabotage(y, sim)
            return original(design, cstep, z0, y, sim, **kw)

        monkeypatch.setattr(replay, "_replay", changed)
    return check_c(d, BUILTIN["manipulator"](), SCENARIOS["manipulator"](), folder, sample_time=ts, seed=3)


@needs_cc
def test_the_c_returns_what_the_simulation_applied_on_a_whole_path(manipulator_doc, tmp_path):
    r = run("codegen", str(manipulator_doc), "--out", str(tmp_path / "c"), "--check", "--seed", "2")
    assert r.exit_code == 0, r.output
    assert "checked: fed the measurements of one simulated path of scenario 'manipulator' (seed 2" in r.text
    assert (
        "within 1e-09 of each one's largest magnitude" in r.text
        and "init_from_y of the first measurement" in r.text
    )
    assert (tmp_path / "c" / "fte_manipulator.c").is_file()


@needs_cc
def test_the_check_compares_every_sample_and_fails_on_a_difference(real_designs, tmp_path, monkeypatch):
    d = real_designs["manipulator"]
    got = _check(d, tmp_path / "a")
    assert got.ok and got.refused is None and got.samples == got.total == 10001
    assert min(got.scale.values()) > 0.1  # the signals move: the comparison is not of zeros
    assert max(got.relative(k) for k in got.diff) <= replay.TOLERANCE

    def nudge(y, sim):  # one sample of u off by 1e-6 of its range, far inside the path
        sim["u"][7000] += 1e-6 * np.max(np.abs(sim["u"]))

    got = _check(d, tmp_path / "b", nudge, monkeypatch)
    assert not got.ok and got.refused is None
    assert 0.9e-6 < got.relative("u") < 1.1e-6
    assert "NOT within 1e-09" in got.render()


@needs_cc
def test_a_measurement_the_c_refuses_fails_the_check_and_is_named(real_designs, tmp_path, monkeypatch):
    d = real_designs["manipulator"]

    def out_of_range(y, sim):
        y[4321, 1] = 1e6

    got = _check(d, tmp_path / "a", out_of_range, monkeypatch)
    assert not got.ok and got.refused == (4321, 3) and got.samples == 4321
    text = got.render()
    assert "its step returned 3 at sample 4321 (t = 4.321)" in text
    assert f"{d.names['outputs'][1]} = 1e+06 outside [" in text and "b.region" in text

    def nan(y, sim):
        y[50, 0] = np.nan

    got = _check(d, tmp_path / "b", nan, monkeypatch)
    assert got.refused == (50, 1) and "a NaN or an infinity" in got.render()


def test_float_is_reported_not_judged():
    r = replay.Replay("s", 0, 0.01, 10, 10, "float", {"u": 0.1, "xbarhat": 0.2, "yc": 0.0},
                      {"u": 1.0, "xbarhat": 1.0, "yc": 1.0}, None, None)  # fmt: skip
    assert r.ok and "reported, not judged" in r.render()
    refused = replay.Replay("s", 0, 0.01, 3, 10, "float", r.diff, r.scale, (3, 1), None)
    assert not refused.ok


def test_check_refuses_what_it_cannot_do_before_writing(manipulator_doc, tmp_path, monkeypatch):
    out = tmp_path / "c"
    monkeypatch.setattr(replay, "find_compiler", lambda: "cc")  # the refusals below come before any compiling
    r = run("codegen", str(manipulator_doc), "--out", str(out), "--check", "--boundary-layer", "0.1")
    assert r.exit_code == 2 and "--check compares the C with fte simulate's step, which runs sgn(s)" in r.text
    r = run("codegen", str(manipulator_doc), "--out", str(out), "--check", "--seed", "-1")
    assert r.exit_code == 2 and "--seed" in r.text
    assert not out.exists() or not any(out.iterdir())
    monkeypatch.setattr(replay, "find_compiler", lambda: None)
    r = run("codegen", str(manipulator_doc), "--out", str(out), "--check")
    assert r.exit_code == 2 and "--check compiles the C: no C compiler found" in r.text
    assert not out.exists() or not any(out.iterdir())


def test_a_boundary_layer_is_refused_unless_it_is_the_designs_own(real_designs):
    d = real_designs["manipulator"]
    own = dataclasses.replace(d, params=dataclasses.replace(d.params, boundary_layer=0.02))
    replay.require_same_sliding(own, 0.02)  # the simulation runs sat(s / 0.02) too
    replay.require_same_sliding(own, None)
    with pytest.raises(
        replay.CodegenError, match=r"which runs the design's sat\(s / 0.02\); with --boundary-layer 0.1"
    ):
        replay.require_same_sliding(own, 0.1)


def test_the_horizon_is_whole_samples_and_a_cut_says_what_it_leaves_out(monkeypatch):
    sc = SCENARIOS["manipulator"]()  # T = 10, fa in [2.5, 5), fs in [7, 10)
    same, cut = replay._horizon(sc, 0.001)
    assert same is sc and cut == ""
    short, cut = replay._horizon(sc, 0.0007)  # 10 is no whole number of 0.0007
    assert short.T == pytest.approx(14285 * 0.0007) and cut.startswith(
        "; the scenario cut at t = 9.9995 of 10"
    )
    assert "left out" not in cut  # both windows start before the cut
    monkeypatch.setattr(replay, "MAX_SAMPLES", 6001)
    short, cut = replay._horizon(sc, 0.001)
    assert short.T == pytest.approx(6.0) and [f.fault for f in short.faults] == ["fa"]
    assert cut == "; the scenario cut at t = 6 of 10 (fault windows left out: fs [7, 10))"


@needs_cc
def test_a_noisy_start_is_checked(real_designs, tmp_path):
    """The three-tank with a noisy level sensor (H != 0): the C's init_from_y starts where the simulation started
    (the start the simulation made before 2026-11-29, from y_0 without its noise, was 0.05 and more away: the
    check would fail on it), and the C then returns what the simulation applied."""
    d, plant = real_designs["three-tank"], BUILTIN["three-tank"]()
    scenario = dataclasses.replace(SCENARIOS["three-tank"](), measurement_noise=(0.5, 0.5)).until(100.0)
    ts = scenario.dt
    generate_c(d, tmp_path, sample_time=ts)
    got = check_c(d, plant, scenario, tmp_path, sample_time=ts, seed=1)
    assert got.ok and got.samples == got.total == 10001
    assert got.start_relative <= 1e-12 and max(got.relative(k) for k in got.diff) <= replay.TOLERANCE
    z0 = first_observer_state(d, plant, scenario, dt=ts, seed=1)
    x0 = np.asarray(simulate(d, plant, scenario, paths=1, seed=1, options=SimulateOptions(
        record_every=1, record_paths=1, progress=False, detect=False)).run("ftc").x)[0, 0]  # fmt: skip
    assert np.max(np.abs(observer_start(d, plant, scenario, x0)[0] - z0)) > 0.05  # without the noise: far off


def test_the_simulation_starts_its_observer_from_the_first_measurement(real_designs):
    """docs/method.md: ``z_0 = xbar0 - H y_0`` with ``y_0`` the first measurement, its noise and a sensor fault
    present at t = 0 included, so that ``xbarhat_0 = xbar0`` in every run, as the C's ``init_from_y`` starts.
    Before, the simulation left them out of ``y_0`` (``xbarhat_0 = xbar0 + H v_0``): a C started by
    ``init_from_y`` on the chemostat of `tests/plant_chemostat.py` (pump fault) then differed from the
    simulation by 0.45 in u, of 0.15, fed the same measurements."""
    d, plant = real_designs["manipulator"], BUILTIN["manipulator"]()
    scenario = dataclasses.replace(
        SCENARIOS["manipulator"](), measurement_noise=(0.05, 0.05, 0.05), faults=(Bias("fs", 0.3, 0.0, 0.5),)
    ).until(0.5)
    opts = SimulateOptions(record_every=1, record_paths=3, progress=False, detect=False)
    res = simulate(d, plant, scenario, paths=3, seed=4, options=opts)
    for run in RUNS:
        xb0 = np.asarray(res.run(run).xbarhat)[:, 0]
        assert np.max(np.abs(xb0 - d.xbar0)) <= 1e-12 * max(1.0, np.max(np.abs(d.xbar0))), run
    y0 = {run: np.asarray(res.run(run).y)[:, 0] for run in RUNS}
    assert np.allclose(y0["ftc"][:, 0] - y0["free"][:, 0], 0.3)  # the sensor fault is in the faulty runs' y_0
    v0 = y0["free"][0] - np.asarray(plant.C) @ np.asarray(res.run("free").x)[0, 0]
    assert np.max(np.abs(np.asarray(d.H) @ v0)) > 1e-3  # the noise reaches z_0 through H: not vacuous
    z0 = first_observer_state(d, plant, scenario, dt=scenario.dt, seed=4, path=2, run="no_ftc")
    xb = np.asarray(res.run("no_ftc").xbarhat)[2, 0]  # z_0 + H y_0, rounded as the engine rounds it
    np.testing.assert_allclose(z0 + np.asarray(d.H) @ y0["no_ftc"][2], xb, rtol=0, atol=1e-14)


@needs_cc
def test_the_fmu_is_fed_the_same_measurements(manipulator_doc, tmp_path):
    """With --fmu, the FMU (through FMPy) must return, step by step, what the C started by init_from_y returns."""
    pytest.importorskip("fmpy")
    r = run("codegen", str(manipulator_doc), "--out", str(tmp_path / "c"), "--fmu", "--check")
    assert r.exit_code == 0, r.output
    said = r.text.split(
        "the FMU, fed the same through FMPy, returns what the C started by init_from_y returns"
    )
    assert len(said) == 2 and said[1].startswith(" (largest difference ")
    assert float(said[1].split("largest difference ")[1].split(")")[0]) <= 1e-9


def test_an_fmu_that_differs_fails_the_check():
    scale = {"u": 1.0, "xbarhat": 1.0, "yc": 1.0}
    same = replay.Replay("s", 0, 0.01, 10, 10, "double", dict.fromkeys(scale, 0.0), scale, None, replay.TOLERANCE,
                         fmu="", fmu_diff=0.0)  # fmt: skip
    assert same.ok
    differs = dataclasses.replace(same, fmu_diff=1e-6)
    assert (
        not differs.ok
        and "the FMU, fed the same through FMPy, does NOT return what the C" in differs.render()
    )
    assert dataclasses.replace(same, fmu_diff=None).ok  # FMPy missing: said, not judged
    failed = dataclasses.replace(same, tolerance=None, fmu="; the FMU does NOT do what the C does: at sample 3 ...",
                                 fmu_diff=math.inf)  # an FMU error fails the check in float too  # fmt: skip
    assert not failed.ok and failed.render().endswith(
        "; the FMU does NOT do what the C does: at sample 3 ..."
    )
