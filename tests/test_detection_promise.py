"""The false-alarm rate a calibration promises, verified on fresh fault-free paths, and what it takes to set it.

The calibration (fte_casadi.sim._detect) sets each fault's thresholds from fault-free paths that are not the
run's own and promises a 95 % interval of the false-alarm rate they deliver, counted by the documented alarm
rule on its own calibration paths. Here the run's own 1000 (fresh, independent) fault-free paths count the
alarms by the same rule (``false_alarm_rate``, with its own 95 % interval: Garwood's exact Poisson interval,
widened by the bootstrap over the paths), and the promise holds when **the two 95 % intervals overlap**: both
are intervals of the same rate, so a promise that is off by more than the two intervals' half-widths fails.
Each check also asks that the fresh count be large (at least 100 alarms) and the promise narrow (its upper
end at most 2.5 times its lower end), so that the comparison can fail.

To count enough alarms on 1000 paths within a test's budget the rate asked is one that can be measured there:
the quadruple tank at the default, one per hour (1000 paths of 600 s hold 146 path-hours after the start-up);
the pendulum example and a plant of a user's own with noise on every sensor (tests/plant_duffing_noisy.py) at
0.05 per second on a 4 s horizon (0.9 path-hours each). The calibration sizes itself for the rate
(``calibration_paths``), at its default budget.
"""

from __future__ import annotations

import dataclasses
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.design import Design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import simulate
from fte_casadi.sim._calibrate import block_samples
from fte_casadi.sim._detect import N_EMPIRICAL, calibration_paths

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = f"{ROOT / 'examples' / 'pendulum_plant.py'}:pendulum"
DUFFING = f"{ROOT / 'tests' / 'plant_duffing_noisy.py'}:duffing"
FRESH = 1000
#: plant spec, committed design (None: designed here), horizon, rate asked (None: the default, one per hour)
CASES = {
    "quadruple-tank": ("quadruple-tank", "quadruple_tank", 600.0, None),
    "pendulum": (PENDULUM, None, 4.0, 0.05),
    "duffing-noisy": (DUFFING, None, 4.0, 0.05),  # a plant of a user's own, with noise on every sensor
}


def designed(spec: str, folder) -> Design:
    """``fte design SPEC`` of this checkout."""
    out = folder / "design.json"
    subprocess.run([sys.executable, "-m", "fte_casadi", "design", spec, "-o", str(out)], check=True,
                   capture_output=True, cwd=ROOT)  # fmt: skip
    return Design.load(out)


def _case(name, tmp_path):
    spec, committed, T, rate = CASES[name]
    plant, scenario = load_plant(spec), load_scenario(spec)
    if committed is None:
        design = designed(spec, tmp_path)
    else:
        design = Design.load(ROOT / "generated" / committed / "design.json")
    # the horizon shortened, the fault windows beyond it left out (the fault-free run does not see them)
    scenario = dataclasses.replace(scenario, T=T, faults=tuple(f for f in scenario.faults if f.stop <= T))
    return design, plant, scenario, rate


#: the pendulum (11 s) checks the promise as the user's noisy plant does, without the noise: `pytest -m heavy`
@pytest.mark.parametrize(
    "name", [pytest.param(k, marks=pytest.mark.heavy) if k == "pendulum" else k for k in CASES]
)
def test_fresh_paths_raise_the_alarms_the_calibration_promises(name, tmp_path, monkeypatch):
    monkeypatch.delenv("FTE_CALIBRATION_BUDGET", raising=False)  # the calibration as a user's run makes it
    design, plant, scenario, rate = _case(name, tmp_path)
    res = simulate(design, plant, scenario, paths=FRESH, seed=1, progress=False, record_paths=0,
                   false_alarm_rate=rate)  # fmt: skip
    m = res.metrics
    assert [e["fault"] for e in m["detection"]] == list(plant.fault_names)
    for e in m["detection"]:
        key = f"{name} {e['fault']}"
        print(key, e["calibration_paths"], e["false_alarm_rate_interval"], e["false_alarm_rate"], e["false_alarm_count"],
              e["false_alarm_rate_measured_interval"], e["false_alarm_rate_asked"])  # fmt: skip
        asked = e["false_alarm_rate_asked"]
        # the calibration is sized for the rate: N_EMPIRICAL expected alarms per block, within the budget
        block = block_samples(m["observer_time_constant"], scenario.T, m["dt"]) * m["dt"]
        assert e["calibration_paths"] == calibration_paths(asked, block, round(scenario.T / m["dt"]))
        assert e["calibration_first_path"] == FRESH
        assert e["calibration_time"] == pytest.approx(e["calibration_paths"] * (scenario.T - m["transient"]))
        promised = e["false_alarm_rate_interval"]
        fresh = e["false_alarm_rate_measured_interval"]
        assert e["false_alarm_count"] >= 100, (
            key,
            e["false_alarm_count"],
        )  # a count that can tell rates apart
        assert 0 < promised[0] and promised[1] <= 2.5 * promised[0], (
            key,
            promised,
        )  # a promise that says something
        assert promised[0] <= asked * 2 and promised[1] >= asked / 2, (
            key,
            promised,
            asked,
        )  # near the rate asked
        assert fresh[0] <= promised[1] and promised[0] <= fresh[1], (
            f"{key}: fresh {e['false_alarm_rate']:.4g} {fresh} outside the promise {promised} "
            f"(asked {asked:.4g}, calibration {e['calibration_paths']} paths)"
        )


def test_the_calibration_uses_enough_fault_free_time_for_the_rate(monkeypatch):
    """N_EMPIRICAL expected alarms in every block of one observer time constant, at least 200 paths, at most the
    budget of path-steps per pass (and never fewer than 16 paths)."""
    monkeypatch.delenv("FTE_CALIBRATION_BUDGET", raising=False)
    hour = 1 / 3600.0
    assert calibration_paths(hour, 66.3, 8000) == int(np.ceil(N_EMPIRICAL / (hour * 66.3)))  # 1358: in budget
    assert calibration_paths(hour, 0.474, 10_000) == 2000  # 190 000 wanted: the budget's 2e7 path-steps
    assert calibration_paths(1.0, 1.0, 100) == 200  # 25 wanted: at least 200
    monkeypatch.setenv("FTE_CALIBRATION_BUDGET", "1e5")
    assert calibration_paths(hour, 0.474, 10_000) == 16
    assert calibration_paths(hour, 0.474, 10_000, given=7) == 7
    monkeypatch.setenv("FTE_CALIBRATION_BUDGET", "-1")
    with pytest.raises(ValueError, match="FTE_CALIBRATION_BUDGET"):
        calibration_paths(hour, 1.0, 10)
