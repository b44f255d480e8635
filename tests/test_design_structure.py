"""Issue #19 item 2: a failed assumption (1) or (2) names the faults and unknown inputs behind it
and the measurement that would separate them."""

from __future__ import annotations

import pytest
from plant_quadtank_leak import measured_twice, plant

from fte_casadi import PlantBuilder
from fte_casadi.design import augment, design
from fte_casadi.design._structure import confounded_sets, undecoupled_inputs
from fte_casadi.design._uio import check_full_column_rank
from fte_casadi.errors import AssumptionError
from fte_casadi.ts import derive


@pytest.fixture(scope="module")
def quadtank():
    return derive(plant(), fidelity_samples=200)


def _aug(ts):
    return augment(ts.local_models, ts.C, ts.Df)


def test_leak_and_level_bias_are_named_with_the_sensor_that_separates_them(quadtank):
    sets = confounded_sets(_aug(quadtank), *(getattr(quadtank.plant, k) for k in
                           ("fault_names", "unknown_input_names", "state_names")))  # fmt: skip
    assert len(sets) == 1
    c = sets[0]
    assert (c.faults, c.unknown_inputs) == (("fs",), ("leak",))
    assert c.rules == tuple(range(1, quadtank.r + 1))  # every rule
    assert c.separating_states == ("dh1",)  # only a second level-1 sensor separates them
    with pytest.raises(AssumptionError) as err:
        design(quadtank)
    msg = " ".join(str(err.value).split())
    assert 'fault "fs" and unknown input "leak" enter the outputs identically' in msg
    assert 'a measurement of "dh1" free of fault "fs" would separate them' in msg


@pytest.mark.slow
def test_the_named_measurement_does_separate_them():
    ts = derive(measured_twice(), fidelity_samples=200)
    aug = _aug(ts)
    assert check_full_column_rank(aug, None).holds
    assert (
        confounded_sets(aug, ts.plant.fault_names, ts.plant.unknown_input_names, ts.plant.state_names) == []
    )


def test_an_unseen_unknown_input_is_named_with_the_state_to_measure():
    b = PlantBuilder("unseen")
    x1, x2 = b.states("pos", "vel")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("gust")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift([x2, -x1 - x2 + u + fa + d])
    b.diffusion([0.0, 0.0])
    b.outputs([x1])
    b.region(pos=(-1.0, 1.0), vel=(-1.0, 1.0))
    ts = derive(b.build(), fidelity_samples=100)
    assert undecoupled_inputs(_aug(ts), ("gust",), ("pos", "vel")) == [(("gust",), ("vel",))]
    with pytest.raises(AssumptionError, match="assumption \\(1\\) fails") as err:
        design(ts, remark5=False)  # with Remark 5 (the default) (1) is handled, and (2) refuses the pair
    assert 'unknown input "gust" moves states the outputs do not see; a measurement of "vel"' in " ".join(
        str(err.value).split()
    )
