"""The FMU of an accommodated design, fed a Monte Carlo path's noisy measurements, equals the Python step."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from tolerances import C_DOUBLE

from fte_casadi.codegen import _build as build
from fte_casadi.codegen._fmu import fmu_variables, generate_fmu
from fte_casadi.design import Design
from fte_casadi.plants import SCENARIOS, load_plant
from fte_casadi.sim import simulate
from fte_casadi.step import step_function

pytestmark = pytest.mark.slow

try:
    import fmpy
except ImportError:  # the optional extra `fmi`
    fmpy = None

ROOT = Path(__file__).resolve().parents[1]
needs = pytest.mark.skipif(
    build.find_compiler() is None or fmpy is None, reason="needs a C compiler and FMPy"
)


@needs
@pytest.mark.parametrize("release", [None, 0.5])
def test_fmu_with_accommodation_on_noisy_measurements(release, tmp_path):
    """u, xbarhat, yc and, with hysteresis (release 0.5), the gates equal the Python step's."""
    d = Design.load(ROOT / "generated/manipulator/design.json")
    rule = {"rule": "isolate", "thresholds": [0.02, 0.008]}
    d = dataclasses.replace(d, accommodation=rule if release is None else {**rule, "release": release})
    sc = dataclasses.replace(SCENARIOS["manipulator"]().until(6.0), measurement_noise=(0.002, 0.002, 0.002))
    res = simulate(d, load_plant("manipulator"), sc, paths=1, seed=4, record_all=True, record_every=1,
                   progress=False, detect=False)  # fmt: skip
    ys = res.ftc.y[0]
    fn = step_function(d, res.dt)
    z = d.observer_start(ys[0])
    ref = []
    for y in ys:
        z, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z, y))
        ref.append(np.concatenate([u, xb, yc, z[d.nbar :]]))  # z ends with a latched gate's gates
    ref = np.array(ref)
    path = generate_fmu(d, tmp_path, sample_time=res.dt)
    names = [v.name for v in fmu_variables(d)]
    p = ys.shape[1]
    signal = np.zeros(len(ys), dtype=[("time", float)] + [(n, float) for n in names[:p]])
    signal["time"] = np.arange(len(ys)) * res.dt
    for j, n in enumerate(names[:p]):
        signal[n] = ys[:, j]
    out = fmpy.simulate_fmu(str(path), start_time=0.0, stop_time=len(ys) * res.dt, output_interval=res.dt,
                            input=signal, output=names[p:])  # fmt: skip
    got = np.column_stack([out[n] for n in names[p:]])
    expected = np.vstack([ref[:1], ref])  # t_0: y_0's sample, then the held samples
    scale = np.maximum(1.0, np.max(np.abs(expected), axis=1))
    assert float(np.max(np.abs(got - expected) / scale[:, None])) <= C_DOUBLE
    m = int(d.dims.m)
    u_all = ref[:, :m]
    fhat = ref[:, m + 4 + 2 : m + 4 + 4]
    closed = np.any(np.abs(fhat) < [0.02, 0.008], axis=1)
    assert closed.any() and (~closed).any()  # the gate was both open and closed along the path
    assert np.all(np.isfinite(u_all))
    if d.latched:
        assert all(n.endswith("_gate") for n in names[-2:])
        gate = got[1:, -2:]
        assert np.array_equal(gate, ref[:, -2:])  # the FMU's gates are exactly the Python step's
        ratio = np.abs(fhat) / [0.02, 0.008]
        assert np.any((gate == 1) & (ratio < 1))  # a latch held a fault below its threshold
