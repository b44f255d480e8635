"""The options records of simulate() and tune() (issue #41 item 3): a bad field is refused with a message naming
it, and a run through the keywords and through the record gives the same metrics (tune's: in
tests/test_tune.py::test_reproducible_for_a_seed)."""

from __future__ import annotations

import dataclasses

import pytest

from fte_casadi.errors import FteError, ParameterError
from fte_casadi.plants import SCENARIOS, load_plant
from fte_casadi.sim import SimulateOptions, simulate
from fte_casadi.tune import TuneOptions


@pytest.mark.parametrize(
    "field, value",
    [("dt", -1e-3), ("dt", float("nan")), ("progress", None), ("record_paths", -1), ("record_all", "yes"),
     ("record_every", 0), ("threads", 0), ("chunk", 2.5), ("scales", {"fault_size": 2.0}),
     ("scales", {"noise_scale": -1.0}), ("scales", [1.0]), ("exact", 1), ("detect", "no"),
     ("false_alarm_rate", 0.0), ("false_alarm_rate", "often"), ("calibration_paths", 1)],
)  # fmt: skip
def test_a_bad_simulate_option_is_refused_naming_it(field, value):
    with pytest.raises(FteError, match=field.split("_")[0]):
        SimulateOptions(**{field: value})


@pytest.mark.parametrize(
    "field, value",
    [("trials", 1), ("trials", None), ("seed", -1), ("seed", 1.5), ("rule", "fastest"), ("paths", 0),
     ("sigma_sup", -2.0), ("base_is_given", 1), ("progress", "bar"), ("storage", 3), ("resume", "yes")],
)  # fmt: skip
def test_a_bad_tune_option_is_refused_naming_it(field, value):
    kw = {"trials": 4, field: value}
    with pytest.raises(ParameterError, match=field):
        TuneOptions(**kw)


def test_the_records_are_frozen_and_replaced():
    o = SimulateOptions(dt=1e-3)
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.dt = 2e-3  # type: ignore[misc]
    assert o.replace(exact=False) == SimulateOptions(dt=1e-3, exact=False)
    t = TuneOptions(trials=5)
    assert t.replace(seed=2).seed == 2 and t.seed == 0
    with pytest.raises(ParameterError, match="trials"):
        t.replace(trials=1)


def _strip(m: dict) -> dict:
    return {k: v for k, v in m.items() if k != "wall_s"}


def test_simulate_through_keywords_and_through_the_record_gives_the_same_metrics(lqr_designs):
    d, plant = lqr_designs["manipulator"], load_plant("manipulator")
    sc = dataclasses.replace(SCENARIOS["manipulator"](), T=1.0)
    sc = dataclasses.replace(sc, faults=tuple(f for f in sc.faults if f.stop <= sc.T))
    kw = dict(progress=False, detect=False, threads=1, record_every=2, scales={"noise_scale": 0.5})
    by_kw = simulate(d, plant, sc, paths=2, seed=3, **kw)
    by_record = simulate(d, plant, sc, paths=2, seed=3, options=SimulateOptions(**kw))
    assert _strip(by_record.metrics) == _strip(by_kw.metrics)
    assert by_record.record_every == by_kw.record_every == 2
    # a keyword other than its default changes the record's field; one at its default leaves it
    mixed = simulate(d, plant, sc, paths=2, seed=3, options=SimulateOptions(**kw).replace(record_every=4),
                     record_every=2, exact=True)  # fmt: skip
    assert mixed.record_every == 2 and _strip(mixed.metrics) == _strip(by_kw.metrics)


def test_simulate_refuses_options_of_another_kind(lqr_designs):
    d, plant = lqr_designs["manipulator"], load_plant("manipulator")
    with pytest.raises(ParameterError, match="SimulateOptions"):
        simulate(d, plant, SCENARIOS["manipulator"](), paths=1, seed=0, options={"dt": 1e-3})
