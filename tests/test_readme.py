"""The README's "Your own plant" code runs as written: its plant and its scenario, through derive,
design and a short simulation (a newcomer copies these two blocks first); docs/your-plant.md shows
the same two blocks."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

from fte_casadi.design import design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import simulate
from fte_casadi.ts import derive

README = Path(__file__).resolve().parents[1] / "README.md"
YOUR_PLANT = Path(__file__).resolve().parents[1] / "docs" / "your-plant.md"


def _blocks(path: Path) -> list[str]:
    return re.findall(r"```python\n(.*?)```", path.read_text(), re.S)


@pytest.mark.slow
def test_readme_plant_and_scenario_run(tmp_path):
    blocks = _blocks(README)
    plant = [b for b in blocks if "def pendulum" in b]
    scen = [b for b in blocks if "def scenario" in b]
    assert len(plant) == 1 and len(scen) == 1, "the README's plant and scenario blocks"
    (tmp_path / "readme_plant.py").write_text(plant[0] + "\n\n" + scen[0])
    spec = f"{tmp_path / 'readme_plant.py'}:pendulum"
    ts = derive(load_plant(spec))
    assert ts.fidelity.max_abs_error <= 1e-9 and len(ts.local_models) == 2
    sc = load_scenario(spec)
    assert {f.fault for f in sc.faults} == {"fa", "fs"}
    d = design(ts, sample_time=sc.dt)
    assert d.certified
    assert tuple(sc.measurement_noise.std) == (0.002, 0.01, 0.003)
    m = simulate(d, ts.plant, sc, paths=2, seed=0, progress=False).metrics
    assert len(m["windows"]) == 2 and all(e is not None and e < 1.0 for e in m["fault_rel_rms_error"])
    assert m["ftc_true_ratio"] < 1.0  # over both windows, on the true outputs
    assert m["measurement_noise"] == [0.002, 0.01, 0.003]


def test_your_plant_page_shows_the_same_plant_and_scenario():
    """docs/your-plant.md repeats the README's two blocks; they are the same code, so the run above
    covers both."""
    readme = [b for b in _blocks(README) if "def pendulum" in b or "def scenario" in b]
    page = [b for b in _blocks(YOUR_PLANT) if "def pendulum" in b or "def scenario" in b]
    assert len(readme) == 2 and page == readme
