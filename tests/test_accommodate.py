"""Accommodation after detection: a fault compensated only while detected and isolated, the same in the C."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from tolerances import C_DOUBLE

from fte_casadi.codegen import build
from fte_casadi.codegen.ctypes_step import CStep
from fte_casadi.codegen.generate import generate_c
from fte_casadi.design.record import Design
from fte_casadi.errors import DesignFileError
from fte_casadi.plants import SCENARIOS
from fte_casadi.plants.loader import load_plant, load_scenario
from fte_casadi.sim import simulate
from fte_casadi.sim.accommodate import accommodated

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = f"{ROOT / 'examples' / 'pendulum_plant.py'}:pendulum"
needs_cc = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    out = tmp_path_factory.mktemp("pend") / "p.json"
    proc = subprocess.run([sys.executable, "-m", "fte_casadi", "design", PENDULUM, "-o", str(out)],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    return Design.load(out), load_plant(PENDULUM), load_scenario(PENDULUM)


@pytest.mark.slow
def test_accommodation_removes_the_cross_talk_that_made_tolerant_control_worse_than_none(pendulum):
    """The pendulum's sensor-fault window: always compensating, the actuator fault's cross-talk (Kf fhat_fa)
    leaves the true outputs several times worse than no tolerant control; compensating a fault only while it
    is detected and isolated keeps it out."""
    d, plant, sc = pendulum
    kw = dict(paths=6, seed=1, progress=False)
    base = simulate(d, plant, sc, **kw)
    acc = accommodated(d, plant, sc, paths=6, seed=1)
    gated = simulate(acc, plant, sc, **kw)
    w_base = next(w for w in base.metrics["windows"] if w["fault"] == "fs")
    w_acc = next(w for w in gated.metrics["windows"] if w["fault"] == "fs")
    assert w_base["ftc_true_ratio"] > 2.0  # worse than none, as the verdict says
    assert w_acc["ftc_true_ratio"] < 0.5 * w_base["ftc_true_ratio"]
    assert w_acc["ftc_true_ratio"] < 1.1
    # the thresholds are the run's own detection thresholds (the same calibration paths)
    assert acc.accommodation["thresholds"] == pytest.approx(
        [e["threshold"] for e in base.metrics["detection"]]
    )
    # the actuator fault is still compensated in its own window: its estimate and the FTC ratio stay useful
    fa = next(w for w in gated.metrics["windows"] if w["fault"] == "fa")
    assert fa["ftc_true_ratio"] < 0.6 and fa["fault_rel_rms_error"] < 0.3


def test_the_document_keeps_the_accommodation_and_refuses_a_bad_one(real_designs, tmp_path):
    d = real_designs["manipulator"]
    acc = dataclasses.replace(d, accommodation={"rule": "isolate", "thresholds": [0.02, 0.01]})
    acc.save(tmp_path / "a.json")
    back = Design.load(tmp_path / "a.json")
    assert back.accommodation["thresholds"] == [0.02, 0.01]
    doc = json.loads((tmp_path / "a.json").read_text())
    for bad in ([0.02], [0.02, -1.0], [0.02, "inf"], [True, 0.1]):
        doc["accommodation"]["thresholds"] = bad
        (tmp_path / "b.json").write_text(json.dumps(doc))
        with pytest.raises(DesignFileError, match="accommodation"):
            Design.load(tmp_path / "b.json")


@pytest.mark.slow
@needs_cc
def test_the_c_step_accommodates_as_the_simulation(real_designs, tmp_path):
    """The generated C of an accommodated design, fed the Monte Carlo's measurements, gives its inputs."""
    d, plant = real_designs["manipulator"], load_plant("manipulator")
    sc = dataclasses.replace(SCENARIOS["manipulator"](), measurement_noise=(0.002, 0.002, 0.002))
    acc = dataclasses.replace(d, accommodation={"rule": "isolate", "thresholds": [0.02, 0.008]})
    res = simulate(
        acc, plant, sc, paths=1, seed=2, record_all=True, record_every=1, progress=False, detect=False
    )
    generate_c(acc, tmp_path, sample_time=res.dt)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), acc, "double")
    ftc = res.ftc
    c.init(ftc.xbarhat[0, 0] - np.asarray(acc.H) @ ftc.y[0, 0])
    scale = max(1.0, float(np.max(np.abs(ftc.y))), float(np.max(np.abs(ftc.u))))
    worst, gated = 0.0, 0
    Kf = np.asarray(acc.Kf)
    for k in range(ftc.y.shape[1]):
        rc, u, xb, yc = c.step(ftc.y[0, k])
        assert rc == 0
        worst = max(
            worst, float(np.max(np.abs(u - ftc.u[0, k]))), float(np.max(np.abs(xb - ftc.xbarhat[0, k])))
        )
        fhat = ftc.fhat[0, k]
        gated += int(np.any(np.abs(fhat) < [0.02, 0.008]) and np.any(Kf @ fhat))
    assert worst <= C_DOUBLE * scale, worst
    assert gated > 0  # the gate was closed on some samples: the comparison exercised it
