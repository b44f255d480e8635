"""A window worse than none where tolerant control applied nothing: what it measures with nothing carried in
(fte_casadi.sim.carry_free, the metrics key carry_free_ratio, the verdict's cause)."""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest

from fte_casadi.design import Design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import _engine, carry_free, simulate
from fte_casadi.verdicts import verdicts

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = "examples/pendulum_plain.py:pendulum"  # the hand-written defaults (pendulum_plant.py has tune's)


def _window(fault, a, b, ratio, comp, per_output=(1.0, 1.0)):
    return {"fault": fault, "start": a, "stop": b, "ftc_true_ratio": ratio, "ftc_true_ratio_interval": [ratio, ratio],
            "ftc_true_ratio_per_output": list(per_output), "ftc_compensation_rms": comp,
            "ftc_true_rms_per_output": {"ftc": [1.0, 1.0], "no_ftc": [1.0, 1.0]}}  # fmt: skip


def test_only_a_window_worse_than_none_with_nothing_applied_and_a_tail_is_measured_again(monkeypatch):
    sc = load_scenario("manipulator")  # fa [2.5, 5), fs [7, 10)
    asked = []

    def fake(design, plant, scenario, *, paths, seed, options):
        asked.append(
            ([(f.fault, f.start) for f in scenario.faults], paths, seed, options.detect, options.record_paths)
        )
        w = _window("fs", 7, 10, 1.0, [0.0])
        w["ftc_true_rms_per_output"] = {"ftc": [3.0, 4.0], "no_ftc": [3.0, 4.0]}
        return SimpleNamespace(metrics={"windows": [w]})

    monkeypatch.setattr(_engine, "simulate", fake)
    m = {"windows": [_window("fa", 2.5, 5, 1.2, [0.0]), _window("fs", 7, 10, 1.01, [0.0])]}
    m["windows"][1]["ftc_true_rms_per_output"] = {"ftc": [3.0, 4.1], "no_ftc": [3.0, 4.0]}
    carry_free(m, None, None, sc, paths=5, seed=3)
    # fa's window: no earlier window; fs's: measured once, alone, on the same paths and seed, without detection
    assert asked == [([("fs", 7.0)], 5, 3, False, 0)]
    assert "carry_free_ratio" not in m["windows"][0]
    assert m["windows"][1]["carry_free_ratio"] == pytest.approx(1.0)  # sqrt(9 + 16) / sqrt(9 + 16)
    assert m["windows"][1]["carry_free_ratio_per_output"] == pytest.approx([1.0, 1.0])
    one = _window("fs", 7, 10, 0.9, [0.0], per_output=(0.8, 1.07))  # an output worse than none: measured too
    carry_free({"windows": [one]}, None, None, sc, paths=5, seed=3)
    assert len(asked) == 2 and "carry_free_ratio" in one
    for skipped in (_window("fs", 7, 10, 0.99, [0.0]), _window("fs", 7, 10, 1.2, [1e-9])):
        asked.clear()
        carry_free({"windows": [skipped]}, None, None, sc, paths=5, seed=3)
        assert not asked and "carry_free_ratio" not in skipped


@pytest.mark.parametrize("value, said", [
    (1.003, "no compensation that removes the earlier faults' effects does better than none"),
    (0.97, "what makes it worse is tolerant control's own tail"),
])  # fmt: skip
def test_the_verdict_names_what_the_window_measures_with_nothing_carried_in(value, said):
    w = _window("fs", 8, 11, 1.0016, [0.0])
    w["onset_deviation"] = {"ftc": 1.16e-5, "no_ftc": 3.32e-5}
    w["carry_free_ratio"] = value
    v = [x for x in verdicts({"windows": [w]}, faults=["fa", "fs"]) if x["verdict"] == "worse than none"]
    text = " ".join(v[0]["text"].split())
    assert "carry_free_ratio" in text and said in text
    # an output worse than none, the whole not: the output's own figure
    w.update(ftc_true_ratio=0.9, ftc_true_ratio_interval=[0.9, 0.9], ftc_true_ratio_per_output=[0.8, 1.07],
             carry_free_ratio=0.5, carry_free_ratio_per_output=[0.4, value])  # fmt: skip
    v = [x for x in verdicts({"windows": [w]}, faults=["fa", "fs"], outputs=["y1", "y2"])
         if x["verdict"] == "worse than none on an output"]  # fmt: skip
    text = " ".join(v[0]["text"].split())
    assert f"would measure {value:.4g} on this output" in text and said in text


@pytest.mark.slow
def test_the_pendulums_sensor_window_is_worse_than_none_by_what_the_run_without_it_carries_in(tmp_path):
    """examples/pendulum_plain.py at its hand-written defaults, 8 paths, seed 1: the sensor window's ratio is above 1
    with no compensation applied in it. With the actuator fault removed from the scenario (nothing carried in) the
    FTC run measures above 1 too, against the same run without tolerant control: recomputed here from the recorded
    arrays of both runs, the number carry_free writes."""
    out = tmp_path / "p.json"
    proc = subprocess.run([sys.executable, "-m", "fte_casadi", "design", PENDULUM, "-o", str(out)],
                          capture_output=True, text=True, cwd=ROOT)  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    d, plant, sc = Design.load(out), load_plant(str(ROOT / PENDULUM)), load_scenario(str(ROOT / PENDULUM))
    kw = dict(paths=8, seed=1, progress=False, detect=False, record_all=True, record_every=1)
    both = simulate(d, plant, sc, **kw)
    m = carry_free(both.metrics, d, plant, sc, paths=8, seed=1)
    fs = next(w for w in m["windows"] if w["fault"] == "fs")
    assert fs["ftc_true_ratio"] > 1 and max(fs["ftc_compensation_rms"]) == 0.0
    alone = simulate(
        d, plant, dataclasses.replace(sc, faults=tuple(f for f in sc.faults if f.fault == "fs")), **kw
    )
    C = np.asarray(d.C, dtype=float)
    inside = (both.t >= fs["start"]) & (both.t < fs["stop"])

    def ms(run, free):
        return float(np.mean(np.sum(((run.x - free.x)[:, inside] @ C.T) ** 2, axis=-1)))

    recomputed = np.sqrt(ms(alone.ftc, alone.free) / ms(both.no_ftc, both.free))
    assert fs["carry_free_ratio"] == pytest.approx(recomputed, rel=1e-9)
    assert fs["carry_free_ratio"] > 1
