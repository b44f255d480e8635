"""A plant in its own units: a building's temperatures in kelvin, its time in seconds, its rates 1e-3 per second
and less (:mod:`plant_house`). The derivation handles absolute units; a reference state the plant cannot rest
at is warned."""

from __future__ import annotations

import pytest
from plant_house import T1_REF, TW_REF, house, house_hours, house_windy, scenario

from fte_casadi.design import design
from fte_casadi.errors import DerivationError
from fte_casadi.ts import derive


def test_a_power_of_a_difference_of_absolute_states_derives_exactly():
    """(Tw - T1)^1.3 is not finite where the premise search sets Tw to 0 with T1 > 0: the order of the states that
    keeps every coefficient finite in the region is taken (it had raised LinAlgError)."""
    ts = derive(house(), fidelity_samples=2000)
    assert ts.r == 4 and ts.fidelity.max_abs_error <= 1e-12


def test_additive_noise_about_an_origin_outside_the_region_says_to_write_deviations():
    with pytest.raises(DerivationError, match=r"additive noise") as exc:
        derive(house_windy())
    msg = " ".join(str(exc.value).split())
    assert (
        "x = 0 lies outside the plant's region (Tw in [300, 360], T1 in [285, 300], T2 in [280, 300])" in msg
    )
    assert "(Tw - 337.434, T1 - 294, T2 - 286.571;" in msg


def test_a_reference_no_input_holds_is_warned_with_the_state_that_moves():
    """One boiler cannot hold both zones where one likes: zone 2 at 290 K with zone 1 at 294 K (it rests at 286.6)."""
    sh = scenario(3600.0)
    bad = design(derive(house(3600.0, reference=[TW_REF, T1_REF, 290.0]), fidelity_samples=500),
                 sample_time=sh.dt, settle_window=0.0)  # fmt: skip
    warned = [s for s in bad.status if "x_ref is not an equilibrium" in s]
    assert len(warned) == 1 and "T2 still moves at" in warned[0] and "K per h" in warned[0]
    good = design(derive(house_hours(), fidelity_samples=500), sample_time=sh.dt, settle_window=0.0)
    assert good.certified and not any("not an equilibrium" in s for s in good.status)
