"""The simulation's engine reads a design's numbers as parameters (fte_casadi.step.StepParameters): the same
numbers as the step with constants (the C's), to the bit, and one compiled engine per structure, not per design."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import casadi as ca
import numpy as np
import pytest

from fte_casadi.design import Design
from fte_casadi.plants import SCENARIOS, manipulator
from fte_casadi.step import StepParameters, step_function

ROOT = Path(__file__).resolve().parents[1]
BUILTIN = ["manipulator", "quadruple-tank", "three-tank"]


def _committed(name: str) -> Design:
    doc = json.loads((ROOT / "generated" / name.replace("-", "_") / "design.json").read_text())
    return Design.from_dict(doc, source=f"generated/{name}")


def _parametrised(design: Design, sample_time: float, tolerant: bool) -> tuple[ca.Function, np.ndarray]:
    numbers = StepParameters()
    step = step_function(design, sample_time, tolerant=tolerant, numbers=numbers)
    z, y = step.sx_in(0), step.sx_in(1)
    fn = ca.Function("p", [z, y, numbers.symbols], step.call([z, y]))
    return fn, numbers.values


@pytest.mark.parametrize("name", BUILTIN)
@pytest.mark.parametrize("tolerant", [True, False])
def test_the_parametrised_step_computes_the_constant_steps_numbers_to_the_bit(name, tolerant):
    d = _committed(name)
    ts = float(d.observer.sample_time)
    folded = step_function(d, ts, tolerant=tolerant)
    fn, values = _parametrised(d, ts, tolerant)
    assert values.size > 0 and np.all(values != 0) and np.unique(values).size == values.size
    rng = np.random.default_rng(3)
    for _ in range(20):
        z = rng.normal(size=d.nz) * rng.choice([1e-3, 1.0, 1e3])
        y = rng.normal(size=int(d.dims.p)) * rng.choice([1e-3, 1.0, 1e3])
        want = [np.asarray(v) for v in folded(z, y)]
        got = [np.asarray(v) for v in fn(z, y, values)]
        for a, b in zip(want, got):
            np.testing.assert_array_equal(a, b)


def test_a_name_given_two_values_is_refused():
    numbers = StepParameters()
    numbers.matrix("K", np.array([[0.5, 2.0]]))
    numbers.matrix("K", np.array([[0.5, 2.0]]))  # the same again: the same matrix
    with pytest.raises(ValueError, match="'K' given two different values"):
        numbers.matrix("K", np.array([[0.5, 3.0]]))


def test_designs_of_one_structure_share_one_compiled_engine():
    """A design with other gains (a tune trial, a design made again) runs in the same compiled engine, reading
    its own numbers: the C source and library are the same, the parameters and the trajectories differ."""
    from fte_casadi.sim._engine import SCALES, Prepared, resolve_dt, run_paths

    plant = manipulator()
    sc = SCENARIOS["manipulator"]().until(3.0)
    d = _committed("manipulator")
    other = dataclasses.replace(d, K=tuple(1.25 * np.asarray(k) for k in d.K))
    dt, nsteps, _ = resolve_dt(d, sc, None)
    a = Prepared(d, plant, sc, dt, nsteps, dict(SCALES))
    b = Prepared(other, plant, sc, dt, nsteps, dict(SCALES))
    assert a.engine.source == b.engine.source and a.engine.lib._name == b.engine.lib._name
    assert a.par.size == b.par.size and not np.array_equal(a.par, b.par)
    ra, rb = run_paths(a, 0, 8, 1, every=50), run_paths(b, 0, 8, 1, every=50)
    assert np.all(np.isfinite(ra[2])) and np.all(np.isfinite(rb[2]))
    assert not np.array_equal(ra[2], rb[2])  # the records: the gains act
