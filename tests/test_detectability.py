"""The smallest fault a design detects (fte_casadi.sim.detectability): the curve, its minimum and the document."""

from __future__ import annotations

import dataclasses
import math
import subprocess
import sys
from pathlib import Path

import pytest

from fte_casadi.design import Design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import detectability
from fte_casadi.sim._detectability import TARGET, _minimum, attach

ROOT = Path(__file__).resolve().parents[1]
DUFFING = f"{ROOT / 'tests' / 'plant_duffing_noisy.py'}:duffing"


def test_the_minimum_is_where_every_larger_size_is_detected():
    factor = [0.25, 0.5, 1.0, 2.0]
    size = [0.1, 0.2, 0.4, 0.8]
    # 0.9 at 0.5, 1.0 at 1: the 95 % is crossed halfway in log(factor) between them
    mdf, f, why = _minimum(factor, [0.2, 0.9, 1.0, 1.0], size)
    assert why is None and f == pytest.approx(math.sqrt(0.5)) and mdf == pytest.approx(0.4 * math.sqrt(0.5))
    # a dip above the crossing moves it up: every factor from the minimum on must reach 95 %
    mdf, f, _ = _minimum(factor, [0.2, 0.96, 0.9, 1.0], size)
    assert f == pytest.approx(math.exp(math.log(1.0) + 0.5 * math.log(2.0)))
    assert _minimum(factor, [0.2, 0.5, 0.6, 0.9], size)[:2] == (None, None)  # never reached: no number
    mdf, f, why = _minimum(factor, [0.97, 1.0, 1.0, 1.0], size)
    assert (mdf, f) == (0.1, 0.25) and "upper bound" in why


def test_attach_takes_the_curve_of_the_run_s_own_noise():
    m = {"detection": [{"fault": "fa", "min_detectable_fault": None}]}
    sets = [{"measurement_noise_scale": 0.0, "curves": [{"fault": "fa", "min_detectable_fault": 0.1}]},
            {"measurement_noise_scale": 1.0, "curves": [{"fault": "fa", "min_detectable_fault": 0.3}]}]  # fmt: skip
    out = attach(m, sets)
    assert out["detection"][0]["min_detectable_fault"] == 0.3 and out["detectability"] is sets
    assert attach(m, sets, noise_scale=0.0)["detection"][0]["min_detectable_fault"] == 0.1
    assert m["detection"][0]["min_detectable_fault"] is None  # the document given is not changed


@pytest.mark.slow
def test_the_curve_with_and_without_measurement_noise(tmp_path):
    """A plant of a user's own with noise on every sensor: the detection probability of its actuator fault
    rises with the fault's size across 95 %, and the noise raises the smallest size detected."""
    out = tmp_path / "design.json"
    subprocess.run([sys.executable, "-m", "fte_casadi", "design", DUFFING, "-o", str(out)], check=True,
                   capture_output=True, cwd=ROOT)  # fmt: skip
    design, plant = Design.load(out), load_plant(DUFFING)
    sc = load_scenario(DUFFING)
    sc = dataclasses.replace(sc, T=6.5, faults=sc.faults[:1])  # the actuator fault's window [3, 6) alone
    kw = dict(paths=32, seed=3, false_alarm_rate=0.05, calibration_paths=200)
    noisy = detectability(design, plant, sc, **kw)
    clean = detectability(design, plant, sc, scales={"measurement_noise_scale": 0.0}, **kw)
    assert noisy["measurement_noise"] == [0.005, 0.02, 0.01] and clean["measurement_noise"] == [0.0, 0.0, 0.0]
    for s in (noisy, clean):
        (c,) = s["curves"]
        tau = -1.0 / design.checks["R_max_real_eig"]  # the observer's slowest time constant
        assert c["fault"] == "fa" and c["delay"] == pytest.approx(min(3 * tau, 3.0), rel=1e-12)
        assert c["factor"] == sorted(c["factor"]) and len(c["factor"]) >= 3
        p = c["probability"]
        assert all(0 <= v <= 1 for v in p) and min(p) < TARGET <= max(p)
        assert all(lo <= v <= hi for v, (lo, hi) in zip(p, c["interval"]))
        # the minimum lies between the last factor below 95 % and the first from which every one reaches it
        k = max(i for i, v in enumerate(p) if v < TARGET)
        assert c["factor"][k] <= c["min_detectable_factor"] <= c["factor"][k + 1]
        assert c["size"][k] <= c["min_detectable_fault"] <= c["size"][k + 1]
        assert s["calibration"][0]["calibration_paths"] == 200
    assert noisy["curves"][0]["min_detectable_fault"] > 2 * clean["curves"][0]["min_detectable_fault"]
    assert noisy["calibration"][0]["threshold"] > clean["calibration"][0]["threshold"]


def test_the_figure_is_written(tmp_path):
    from fte_casadi.plot import detectability_figure

    curve = {"fault": "fa", "delay": 1.4, "factor": [0.5, 1.0, 2.0], "size": [0.1, 0.2, 0.4],
             "probability": [0.3, 0.9, 1.0], "interval": [[0.2, 0.4], [0.8, 0.95], [0.9, 1.0]],
             "min_detectable_fault": 0.25, "min_detectable_factor": 1.2, "why": None}  # fmt: skip
    sets = [{"target": 0.95, "label": "without measurement noise", "curves": [curve]},
            {"target": 0.95, "label": "with measurement noise", "curves": [{**curve, "min_detectable_fault": None}]}]  # fmt: skip
    path = detectability_figure(sets, "p", tmp_path)
    assert path.name == "detectability.png" and path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
