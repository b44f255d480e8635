"""A plant in its own units: a building's temperatures in kelvin, its time in seconds, its rates 1e-3 per second
and less (:mod:`plant_house`). The derivation handles absolute units; a reference state the plant cannot rest
at is warned; where the design is refused in seconds, the refusal names the time unit, with the unit in which the
same plant certifies, checked; the check's model is the plant written in that unit."""

from __future__ import annotations

import numpy as np
import pytest
from plant_cstr import cstr
from plant_house import T1_REF, TW_REF, house, house_hours, house_windy, scenario

from fte_casadi.design import design, u_reference
from fte_casadi.design.diagnose._time_unit import TimeUnit, time_scaled_model, unit_for
from fte_casadi.errors import DerivationError, InfeasibleDesignError
from fte_casadi.plants import manipulator, quadruple_tank, three_tank
from fte_casadi.ts import derive


def test_a_power_of_a_difference_of_absolute_states_derives_exactly():
    """(Tw - T1)^1.3 is not finite where the premise search sets Tw to 0 with T1 > 0: the order of the states that
    keeps every coefficient finite in the region is taken (it had raised LinAlgError)."""
    ts = derive(house(), fidelity_samples=2000)
    assert ts.r == 4 and ts.fidelity.max_abs_error <= 1e-12


def test_additive_noise_about_an_origin_outside_the_region_says_whether_deviations_remove_it():
    with pytest.raises(DerivationError, match=r"additive noise") as exc:
        derive(house_windy())  # the wind's heat flow is proportional to T1 - To, To outside the region
    msg = " ".join(str(exc.value).split())
    assert (
        "x = 0 lies outside the plant's region (Tw in [300, 360], T1 in [285, 300], T2 in [280, 300])" in msg
    )
    assert "the noise does not vanish at the reference state either ([-7.8e-05] there" in msg
    assert "writing deviations does not change that" in msg
    with pytest.raises(DerivationError, match=r"additive noise") as exc:
        derive(house(wind=0.1, wind_about=T1_REF))  # proportional to the deviation from the reference
    msg = " ".join(str(exc.value).split())
    assert (
        "the noise vanishes at the reference state: write the states as deviations from it (Tw - 337.434"
        in msg
    )


def test_the_time_scaled_model_is_the_plant_written_in_that_unit():
    """In hours the drift is 3600 times the drift in seconds, and a noise of intensity s per sqrt(s) is one of
    60 s per sqrt(h): the boiler's 2 % per sqrt(s) enters G 60 times larger."""
    ts = derive(house(boiler_noise=0.02), fidelity_samples=500)
    th = derive(house(3600.0, boiler_noise=0.02), fidelity_samples=500)
    scaled = time_scaled_model(ts, 3600.0)
    assert np.any(scaled.local_models[0].G)
    for a, b in zip(scaled.local_models, th.local_models):
        for k in ("A", "B", "Bd", "Bf", "W", "G", "Gf", "a"):
            np.testing.assert_allclose(getattr(a, k), getattr(b, k), rtol=1e-12, atol=1e-15)
    x, u = np.array([331.0, 293.5, 289.0]), np.array([900.0])
    f0 = np.zeros(2)
    fs = scaled.plant.drift_function()(x, u, np.zeros(0), f0)
    fh = th.plant.drift_function()(x, u, np.zeros(0), f0)
    np.testing.assert_allclose(np.asarray(fs).ravel(), np.asarray(fh).ravel(), rtol=1e-12)
    gs = scaled.plant.diffusion_function()(x, u, f0, np.zeros(0))
    gh = th.plant.diffusion_function()(x, u, f0, np.zeros(0))
    np.testing.assert_allclose(np.asarray(gs).ravel(), np.asarray(gh).ravel(), rtol=1e-12)


def test_plants_near_unit_rates_are_not_rescaled():
    for plant in (manipulator(), three_tank(), quadruple_tank(), house_hours()):
        assert unit_for(derive(plant, fidelity_samples=200)) is None
    assert unit_for(derive(house(), fidelity_samples=200)) == (3600.0, "hour")


@pytest.mark.slow
def test_a_slow_plant_in_seconds_is_refused_naming_its_time_unit_and_certifies_in_hours():
    sc = scenario()
    with pytest.raises(InfeasibleDesignError) as exc:
        design(derive(house()), sample_time=sc.dt, settle_window=40000.0)
    found = exc.value.refusal.found
    assert isinstance(found, TimeUnit) and found.c == 3600.0 and found.unit == "s"
    msg = " ".join(str(exc.value).split())
    assert "The plant's time unit is the cause: its fastest rate is 0.00122 per s" in msg
    assert "The same plant with its time in hours (3600 s" in msg
    # the advice, followed: the plant written in hours, its scenario's times / 3600
    sh = scenario(3600.0)
    d = design(derive(house_hours()), sample_time=sh.dt, settle_window=40000.0 / 3600.0)
    # the numbers quoted are this design's, to the precision of the search (the two models differ in round-off, and
    # the decay rate's bisection stops at 10 %)
    assert d.certified and d.params.sigma == pytest.approx(found.sigma, rel=0.1)
    assert d.observer.alpha == pytest.approx(found.alpha, rel=0.1)


def test_a_reference_no_input_holds_is_warned_with_the_state_that_moves():
    """One boiler cannot hold both zones where one likes: zone 2 at 290 K with zone 1 at 294 K (it rests at 286.6)."""
    sh = scenario(3600.0)
    bad = design(derive(house(3600.0, reference=[TW_REF, T1_REF, 290.0]), fidelity_samples=500),
                 sample_time=sh.dt, settle_window=0.0)  # fmt: skip
    warned = [s for s in bad.status if "x_ref is not an equilibrium" in s]
    assert (
        len(warned) == 1
        and "T2 still moves at -1.73 K per h, 0.18 of its largest rate over the region" in warned[0]
    )
    good = design(derive(house_hours(), fidelity_samples=500), sample_time=sh.dt, settle_window=0.0)
    assert good.certified and not any("not an equilibrium" in s for s in good.status)
    # a textbook's steady state rounded to its printed digits (Seborg's CSTR: 3.3e-5 of the concentration's largest
    # rate over the region left at x_ref) is no reason to warn
    ts = derive(cstr(), fidelity_samples=200)
    status: list = []
    u_reference(ts, [np.zeros((ts.m, ts.n))] * ts.r, status)
    assert not any("not an equilibrium" in s for s in status) and any(
        "drift residual 3.4e-05" in s for s in status
    )
