"""Measurement noise: in the scenario, the Monte Carlo, the sweep, and the C step run on the noisy readings."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from tolerances import C_DOUBLE

from fte_casadi.codegen import CStep, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.errors import ParameterError
from fte_casadi.plants import SCENARIOS, load_plant
from fte_casadi.sim import Scenario, simulate
from fte_casadi.sim._sweep import sweep

needs_cc = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")


def _short(name: str, noise) -> Scenario:
    sc = SCENARIOS[name]()
    return dataclasses.replace(sc, T=1.0, faults=(), measurement_noise=noise)


def test_noise_is_added_to_y_reproducibly(real_designs):
    d, plant = real_designs["manipulator"], load_plant("manipulator")
    std = (0.01, 0.0, 0.02)
    sc = _short("manipulator", std)
    kw = dict(paths=3, seed=4, record_all=True, record_every=1, progress=False, detect=False)
    a = simulate(d, plant, sc, **kw)
    b = simulate(d, plant, sc, chunk=8, threads=1, **kw)
    np.testing.assert_array_equal(a.free.y, b.free.y)  # the same noise whatever the split of the paths
    v = a.free.y - a.free.x @ np.asarray(d.C).T  # fault-free: y = C x + v
    for k, s in enumerate(std):
        if s == 0:
            assert np.all(v[:, :, k] == 0)
        else:
            assert abs(np.std(v[:, :, k]) / s - 1) < 0.05  # 3003 draws per path
            assert abs(np.mean(v[:, :, k])) < 4 * s / np.sqrt(v[:, :, k].size)
    np.testing.assert_array_equal(
        a.free.y - a.free.x @ np.asarray(d.C).T, a.ftc.y - a.ftc.x @ np.asarray(d.C).T
    )
    c = simulate(d, plant, sc, **{**kw, "seed": 5})
    assert not np.array_equal(c.free.y, a.free.y)
    assert a.metrics["measurement_noise"] == list(std)


def test_noise_of_the_wrong_size_and_a_scale_without_noise_are_refused(real_designs):
    d, plant = real_designs["manipulator"], load_plant("manipulator")
    with pytest.raises(ParameterError, match="3 outputs"):
        simulate(d, plant, _short("manipulator", (0.1, 0.1)), paths=1, seed=0, progress=False)
    with pytest.raises(ParameterError, match="negative"):
        Scenario(name="x", T=1.0, dt=0.1, measurement_noise=(-1.0,))
    with pytest.raises(ParameterError, match="no measurement noise"):
        simulate(d, plant, _short("manipulator", None), paths=1, seed=0, progress=False,
                 scales={"measurement_noise_scale": 2.0})  # fmt: skip


@pytest.mark.slow
def test_sweep_over_measurement_noise(real_designs):
    d, plant = real_designs["manipulator"], load_plant("manipulator")
    sc = dataclasses.replace(SCENARIOS["manipulator"](), measurement_noise=(0.002, 0.002, 0.002))
    pts = sweep(d, plant, sc, {"measurement_noise_scale": [0.0, 4.0]}, paths=4, seed=1, progress=False)
    quiet, loud = (p["metrics"] for p in pts)
    assert quiet["measurement_noise"] == [0.0, 0.0, 0.0] and loud["measurement_noise"] == [0.008] * 3
    # more sensor noise: a worse fault estimate (both faults) and a worse state estimate
    assert all(b > a for a, b in zip(quiet["fault_rel_rms_error"], loud["fault_rel_rms_error"]))
    assert sum(loud["state_rms_error"]) > sum(quiet["state_rms_error"])


@pytest.mark.slow
@needs_cc
@pytest.mark.parametrize("name", ["manipulator", "three-tank"])
def test_the_c_step_on_the_noisy_readings_gives_the_simulation(name, real_designs, tmp_path):
    """The generated C fed the Monte Carlo's own noisy measurements (FTC run, faults on) returns the inputs,
    estimates and compensated readings that the simulation recorded, sample by sample."""
    d, plant = real_designs[name], load_plant(name)
    sc = SCENARIOS[name]()
    T = 6.0 if name == "manipulator" else 260.0
    faults = tuple(fp for fp in sc.faults if fp.stop <= T)
    ranges = [0.01, 0.01, 0.01] if name == "manipulator" else [0.05, 0.05]
    sc = dataclasses.replace(sc, T=T, faults=faults, measurement_noise=tuple(ranges))
    res = simulate(
        d, plant, sc, paths=1, seed=3, record_all=True, record_every=1, progress=False, detect=False
    )
    generate_c(d, tmp_path, sample_time=res.dt)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), d, "double")
    ftc = res.ftc
    H = np.asarray(d.H)
    c.init(ftc.xbarhat[0, 0] - H @ ftc.y[0, 0])  # the observer state the simulation started from
    scale = max(1.0, float(np.max(np.abs(ftc.y))), float(np.max(np.abs(ftc.u))))
    worst = 0.0
    for k in range(ftc.y.shape[1]):
        rc, u, xb, yc = c.step(ftc.y[0, k])
        assert rc == 0
        worst = max(worst, float(np.max(np.abs(u - ftc.u[0, k]))), float(np.max(np.abs(xb - ftc.xbarhat[0, k]))),
                    float(np.max(np.abs(yc - ftc.yc[0, k]))))  # fmt: skip
    assert worst <= C_DOUBLE * scale, worst
    assert np.max(np.abs(ftc.fhat[0])) > 0  # the fault was there and estimated
