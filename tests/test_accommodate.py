"""Accommodation after detection: a fault compensated only while detected and isolated, the same in the C."""

from __future__ import annotations

import dataclasses
import json
import subprocess
import sys
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from tolerances import C_DOUBLE

from fte_casadi.codegen import CStep, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.design import Design
from fte_casadi.errors import DesignFileError
from fte_casadi.plants import SCENARIOS, load_plant, load_scenario
from fte_casadi.sim import accommodated, simulate
from fte_casadi.step import accommodation_gate, step_function

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = f"{ROOT / 'examples' / 'pendulum_plant.py'}:pendulum"
needs_cc = pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")


@pytest.fixture(scope="module")
def pendulum(tmp_path_factory):
    out = tmp_path_factory.mktemp("pend") / "p.json"
    proc = subprocess.run([sys.executable, "-m", "fte_casadi", "design", PENDULUM, "-o", str(out)],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    d = Design.load(out)
    # fte design writes its gate (its faults' estimates cross-talk)
    assert d.accommodation["rule"] == "explain"
    # the paper's policy, every estimate compensated always: what the gates are measured against
    return dataclasses.replace(d, accommodation=None), load_plant(PENDULUM), load_scenario(PENDULUM)


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


@pytest.mark.slow
def test_the_gate_compensates_no_cross_talk_after_a_sensor_fault_ends(tmp_path):
    """The pendulum as `fte design` writes it, after its sensor window [8, 11) (no fault in the plant): with the
    cross-talk taken at a step's start alone the gate compensated the torque estimate's cross-talk from the
    sensor fault's end, and tolerant control left the true outputs 22 times farther from the fault-free run than
    none did over [11, 14) (8 paths). Both edges: 1.08. Recomputed from the recorded arrays."""
    out = tmp_path / "p.json"
    proc = subprocess.run([sys.executable, "-m", "fte_casadi", "design", PENDULUM, "-o", str(out)],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    d, plant, sc = Design.load(out), load_plant(PENDULUM), load_scenario(PENDULUM)
    assert d.accommodation["rule"] == "explain"
    res = simulate(
        d, plant, sc, paths=4, seed=1, progress=False, detect=False, record_all=True, record_every=1
    )
    C = np.asarray(d.C, dtype=float)
    after = (res.t >= 11.0) & (res.t < 14.0)

    def ss(run):
        return float(np.sum(((run.x - res.free.x)[:, after] @ C.T) ** 2))

    assert np.sqrt(ss(res.ftc) / ss(res.no_ftc)) < 1.5


def test_the_document_keeps_the_accommodation_and_refuses_a_bad_one(real_designs, tmp_path):
    d = real_designs["manipulator"]
    acc = dataclasses.replace(d, accommodation={"rule": "isolate", "thresholds": [0.02, 0.01]})
    acc.save(tmp_path / "a.json")
    back = Design.load(tmp_path / "a.json")
    assert back.accommodation["thresholds"] == [0.02, 0.01]
    doc = json.loads((tmp_path / "a.json").read_text())
    assert "release" not in back.accommodation and not back.latched and back.nz == back.nbar  # memoryless
    for bad in ([0.02], [0.02, -1.0], [0.02, "inf"], [True, 0.1]):
        doc["accommodation"]["thresholds"] = bad
        (tmp_path / "b.json").write_text(json.dumps(doc))
        with pytest.raises(DesignFileError, match="accommodation"):
            Design.load(tmp_path / "b.json")
    doc["accommodation"]["thresholds"] = [0.02, 0.01]
    for good, latched in ((0.5, True), (1, False)):
        doc["accommodation"]["release"] = good
        (tmp_path / "b.json").write_text(json.dumps(doc))
        back = Design.load(tmp_path / "b.json")
        assert back.accommodation["release"] == good and back.latched is latched
        assert back.nz == back.nbar + (2 if latched else 0)
    for bad in (0, -0.5, 1.5, "0.5", None, True):
        doc["accommodation"]["release"] = bad
        (tmp_path / "b.json").write_text(json.dumps(doc))
        with pytest.raises(DesignFileError, match="release"):
            Design.load(tmp_path / "b.json")


def test_the_document_checks_the_held_crosstalk_and_the_faults_never_compensated(tmp_path):
    d = Design.load(Path(__file__).resolve().parents[1] / "generated" / "quadruple_tank" / "design.json")
    assert d.accommodation["rule"] == "explain" and "crosstalk_held" in d.accommodation
    d.save(tmp_path / "a.json")
    doc = json.loads((tmp_path / "a.json").read_text())
    for key, bad in (("crosstalk_held", [[0.0, 1.0]]), ("crosstalk_held", [[0.0, -1.0], [1.0, 0.0]]),
                     ("never", [2]), ("never", [0, 0]), ("never", [True]), ("never", 0), ("never", ["fa"])):  # fmt: skip
        (tmp_path / "b.json").write_text(
            json.dumps({**doc, "accommodation": {**doc["accommodation"], key: bad}})
        )
        with pytest.raises(DesignFileError, match=f"accommodation.{key}"):
            Design.load(tmp_path / "b.json")
    (tmp_path / "b.json").write_text(
        json.dumps({**doc, "accommodation": {**doc["accommodation"], "never": [1, 0]}})
    )
    assert Design.load(tmp_path / "b.json").accommodation["never"] == [0, 1]


@pytest.mark.parametrize("rule", ["isolate", "explain"])
def test_a_fault_never_compensated_has_its_gate_shut(rule):
    """accommodation.never shuts the listed fault's gate whatever its estimate; the others' gates are the rule's."""
    acc = {"rule": rule, "thresholds": [0.1, 0.1], "crosstalk": [[0.0, 0.0], [0.0, 0.0]]}
    f = np.array([[5.0, 0.0, 5.0, -3.0], [0.0, 5.0, 5.0, 0.2]])
    latch = np.zeros((2, 4))
    before = np.array(_gate_fn(acc, 2, False)(f, latch))
    after = np.array(_gate_fn({**acc, "never": [0]}, 2, False)(f, latch))
    assert before[0].any() and not after[0].any()
    assert np.array_equal(after[1], before[1]) and after[1].any()


def _gate_fn(acc: dict, lf: int, latched: bool):
    fhat, latch = ca.SX.sym("f", lf), ca.SX.sym("g", lf)
    return ca.Function("g", [fhat, latch], [accommodation_gate(fhat, acc, latch if latched else None)])


def test_a_release_of_one_is_the_memoryless_gate():
    """With the release ratio 1 the latches change nothing: whatever they hold, the gate is the memoryless one
    (a latched fault with ratio >= 1 and no larger ratio switches on anyway; a larger ratio >= 1 means the
    largest fault switches on, and releases it)."""
    thr = [0.02, 0.01, 0.05]
    memoryless = _gate_fn({"thresholds": thr}, 3, False)
    one = _gate_fn({"thresholds": thr, "release": 1.0}, 3, True)
    rng = np.random.default_rng(0)
    f = rng.uniform(-2, 2, size=(3, 4000)) * np.array(thr)[:, None]
    f[:, :200] = np.array(thr)[:, None] * rng.choice([0.5, 1.0, 1.5], size=(3, 200))  # ties and edges
    latches = rng.integers(0, 2, size=(3, 4000)).astype(float)
    a, b = np.array(memoryless(f, latches)), np.array(one(f, latches))
    assert np.array_equal(a, b)
    assert 0 < a.sum() < a.size


def test_the_latch_switches_on_holds_and_releases():
    """Fault 0 switches on at ratio 1, holds down to the release ratio, releases below it; a larger ratio of
    another fault releases it only once that fault itself switches on."""
    thr = [1.0, 1.0]
    g = _gate_fn({"thresholds": thr, "release": 0.5}, 2, True)

    def run(seq):
        latch, out = np.zeros(2), []
        for f in seq:
            latch = np.array(g(f, latch)).ravel()
            out.append(latch.tolist())
        return out

    assert run([[0.9, 0], [1.0, 0], [0.7, 0], [0.5, 0], [0.49, 0], [0.7, 0]]) == [
        [0, 0], [1, 0], [1, 0], [1, 0], [0, 0], [0, 0]]  # fmt: skip
    # fault 1 above fault 0 but below its threshold: 0 holds; once 1 switches on (and is larger), 0 releases
    assert run([[1.2, 0], [0.8, 0.9], [0.8, 1.1], [0.8, 0.7], [0.2, 0.6]]) == [
        [1, 0], [1, 0], [0, 1], [0, 1], [0, 1]]  # fmt: skip
    # sign does not matter; a tie switching on keeps both
    assert run([[-1.5, 0], [1.5, -1.5]]) == [[1, 0], [1, 1]]


@pytest.mark.slow
@needs_cc
@pytest.mark.parametrize("release", [None, 0.5])
def test_the_c_step_accommodates_as_the_simulation(release, real_designs, tmp_path):
    """The generated C of an accommodated design, fed the Monte Carlo's measurements, gives its inputs; with
    hysteresis (release 0.5) its latches are the Python step's gates, sample by sample, on a path where a
    latch holds a fault below its threshold."""
    d, plant = real_designs["manipulator"], load_plant("manipulator")
    sc = dataclasses.replace(SCENARIOS["manipulator"](), measurement_noise=(0.002, 0.002, 0.002))
    rule = {"rule": "isolate", "thresholds": [0.02, 0.008]}
    acc = dataclasses.replace(d, accommodation=rule if release is None else {**rule, "release": release})
    res = simulate(
        acc, plant, sc, paths=1, seed=2, record_all=True, record_every=1, progress=False, detect=False
    )
    generate_c(acc, tmp_path, sample_time=res.dt)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), acc, "double")
    ftc = res.ftc
    z = np.concatenate([ftc.xbarhat[0, 0] - np.asarray(acc.H) @ ftc.y[0, 0], np.zeros(acc.nz - acc.nbar)])
    c.init(z)
    fn = step_function(acc, res.dt)
    scale = max(1.0, float(np.max(np.abs(ftc.y))), float(np.max(np.abs(ftc.u))))
    worst, gated, held, gates = 0.0, 0, 0, []
    Kf = np.asarray(acc.Kf)
    for k in range(ftc.y.shape[1]):
        rc, u, xb, yc = c.step(ftc.y[0, k])
        assert rc == 0
        z, u_py, *_ = (np.asarray(v).ravel() for v in fn(z, ftc.y[0, k]))
        worst = max(
            worst, float(np.max(np.abs(u - ftc.u[0, k]))), float(np.max(np.abs(xb - ftc.xbarhat[0, k]))),
            float(np.max(np.abs(u_py - ftc.u[0, k]))),
        )  # fmt: skip
        fhat = ftc.fhat[0, k]
        ratio = np.abs(fhat) / [0.02, 0.008]
        gated += int(np.any(ratio < 1) and np.any(Kf @ fhat))
        if acc.latched:
            assert np.array_equal(c.gate, z[acc.nbar :]), k  # the C's latches are the Python step's gates
            held += int(np.any((c.gate == 1) & (ratio < 1) & (ratio >= 0.5)))
            gates.append(c.gate)
    assert worst <= C_DOUBLE * scale, worst
    assert gated > 0  # the gate was closed on some samples: the comparison exercised it
    if acc.latched:
        assert held > 0  # a latch held a fault between the release ratio and its threshold
        assert set(np.unique(gates)) == {0.0, 1.0}


@pytest.mark.slow
@needs_cc
def test_the_c_step_of_a_gate_with_held_crosstalk_and_a_fault_never_compensated(tmp_path):
    """The committed manipulator design (rule "explain", its memories and crosstalk_held) with its actuator fault
    listed in ``never``: the Monte Carlo applies no compensation at any sample (its sensor fault's column of Kf is
    zero), and the generated C, fed the run's measurements, gives the run's inputs and estimates."""
    d = Design.load(ROOT / "generated" / "manipulator" / "design.json")
    assert d.remembers and "crosstalk_held" in d.accommodation
    off = dataclasses.replace(d, accommodation={**d.accommodation, "never": [0]})
    plant, sc = load_plant("manipulator"), SCENARIOS["manipulator"]()
    res = simulate(
        off, plant, sc, paths=1, seed=2, record_all=True, record_every=1, progress=False, detect=False
    )
    ftc = res.ftc
    assert np.max(np.abs(ftc.ucomp)) == 0.0 and np.max(np.abs(ftc.fhat[0, :, 0])) > 0.1
    generate_c(off, tmp_path, sample_time=res.dt)
    c = CStep(build.compile_shared(tmp_path, tmp_path / "libstep.so"), off, "double")
    c.init(np.concatenate([ftc.xbarhat[0, 0] - np.asarray(off.H) @ ftc.y[0, 0], np.zeros(off.nz - off.nbar)]))
    scale = max(1.0, float(np.max(np.abs(ftc.y))), float(np.max(np.abs(ftc.u))))
    worst = 0.0
    for k in range(ftc.y.shape[1]):
        rc, u, xb, _ = c.step(ftc.y[0, k])
        assert rc == 0
        worst = max(
            worst, float(np.max(np.abs(u - ftc.u[0, k]))), float(np.max(np.abs(xb - ftc.xbarhat[0, k])))
        )
    assert worst <= C_DOUBLE * scale, worst
