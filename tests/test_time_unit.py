"""A plant in its own units: a building's temperatures in kelvin, its time in seconds, its rates 1e-3 per second
and less (:mod:`plant_house`). The derivation handles absolute units."""

from __future__ import annotations

import pytest
from plant_house import house, house_windy

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
