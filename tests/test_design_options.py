"""Tests of fte_casadi.design._options: the design's settings as one frozen record, what was given kept apart
from what it resolved to, and retries that change the record (the plant's own alpha stays the plant's)."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from fte_casadi.design import DesignOptions, design
from fte_casadi.design._options import resolve
from fte_casadi.design.core import _conditioned as cond
from fte_casadi.design.core import _step5
from fte_casadi.errors import ParameterError
from fte_casadi.plants import SCENARIOS


def test_the_record_is_frozen_and_changed_by_replace():
    o = DesignOptions(sigma=0.2, solver="scs")
    assert o.solver == "SCS"  # normalised once, on construction
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.sigma = 0.3
    p = dataclasses.replace(o, gamma=2.0)
    assert (p.sigma, p.gamma, p.solver) == (0.2, 2.0, "SCS") and o.gamma is None
    assert o.replace(gamma=2.0) == p


@pytest.mark.parametrize("kw,field", [({"gamma": -1.0}, "gamma"), ({"sigma": float("nan")}, "sigma"),
                                      ({"gamma2": 0.0}, "gamma2"), ({"kappa": 1.0}, "kappa"),
                                      ({"bound_weight": -1}, "bound_weight"), ({"alpha": True}, "alpha"),
                                      ({"sample_time": 0}, "sample_time"), ({"variant": "fancy"}, "variant"),
                                      ({"solver": "MOSEK9"}, "solver")])  # fmt: skip
def test_bad_settings_are_refused_on_construction_naming_the_field(kw, field):
    with pytest.raises(ParameterError, match=f"^{field} "):
        DesignOptions(**kw)


def test_resolution_keeps_what_was_given_apart(ts_models):
    """The plant's recorded alpha resolves to source "plant"; a given one to "user"; the record is unchanged."""
    ts = ts_models["three-tank"]
    plant_alpha = ts.plant.design_defaults["alpha"]
    o = DesignOptions(sample_time=0.1)
    r = resolve(ts, o)
    assert (r.alpha, r.alpha_source) == (plant_alpha, "plant") and o.alpha is None
    r2 = resolve(ts, o.replace(alpha=plant_alpha))
    assert (r2.alpha, r2.alpha_source) == (plant_alpha, "user")
    assert r.params == r2.params and r.params["gamma"] == ts.plant.design_defaults["gamma"]
    with pytest.raises(ParameterError, match="initial_state must hold 3 finite numbers"):
        resolve(ts, o.replace(initial_state=[1.0, 2.0]))


def test_keywords_and_the_record_give_the_same_design(ts_models):
    ts = ts_models["manipulator"]
    a = design(ts, sample_time=1e-3, sigma=0.2)
    b = design(ts, DesignOptions(sample_time=1e-3, sigma=0.2))
    c = design(ts, DesignOptions(sample_time=1e-3), sigma=0.2)  # keywords change the record
    for d in (b, c):
        assert np.array_equal(d.Pbar, a.Pbar) and np.array_equal(d.K[0], a.K[0]) and d.params == a.params


def test_a_retry_keeps_the_plants_alpha_a_default(ts_models, monkeypatch):
    """The three-tank records its own alpha (fte tune's). When the first solver fails numerically the design is
    retried with the other; the retry is the same record with the solver changed, so it resolves the plant's
    alpha as the plant's default again (not as a rate the user set): it gives the very design asked of the
    other solver directly, and its observer says where alpha came from."""
    ts = ts_models["three-tank"]
    dt = SCENARIOS["three-tank"]().dt
    direct = design(ts, sample_time=dt, solver="SCS")
    step5 = _step5.step5

    def clarabel_fails(aug, params, X, K, T, solver, **kw):
        if solver == "CLARABEL":
            raise cond.SolverFailedError("numerical trouble (made by the test)")
        return step5(aug, params, X, K, T, solver, **kw)

    monkeypatch.setattr(_step5, "step5", clarabel_fails)
    retried = design(ts, sample_time=dt)
    assert retried.solver == "SCS" and retried.status[0].startswith("CLARABEL failed numerically in step 5")
    assert retried.observer.why == direct.observer.why == "the plant's design defaults (fte tune's choice)"
    assert "set by the user" not in retried.observer.why
    assert retried.observer.alpha == direct.observer.alpha
    assert np.array_equal(retried.Pbar, direct.Pbar) and retried.status[1:] == direct.status


def test_a_fraction_of_the_default_rate_is_the_design_at_that_rate_with_step_3_made_once(monkeypatch):
    """fte tune's knob alpha_scale: ``design_at_rate_fraction(ts, f)`` is the design at f times the rate the design
    takes by default, to the bit, and it makes step 3 once for both (the design made twice made it twice)."""
    from pathlib import Path

    from fte_casadi.design import design_at_rate_fraction
    from fte_casadi.plants import load_plant, load_scenario
    from fte_casadi.ts import derive

    spec = f"{Path(__file__).parent / 'plant_tune.py'}:plant"
    ts, scenario = derive(load_plant(spec)), load_scenario(spec)
    kw = dict(sample_time=scenario.dt, initial_state=scenario.x0, diagnose=False)
    calls = []
    step3 = cond.step3
    monkeypatch.setattr(cond, "step3", lambda *a, **k: calls.append(1) or step3(*a, **k))
    a0 = design(ts, **kw).observer.alpha
    apart = design(ts, alpha=0.4 * a0, **kw)
    assert len(calls) == 2
    together = design_at_rate_fraction(ts, 0.4, **kw)
    assert len(calls) == 3 and together.certified and together.observer.alpha == 0.4 * a0
    for name in ("Pbar", "N", "X", "T", "H"):
        np.testing.assert_array_equal(getattr(together, name), getattr(apart, name), err_msg=name)
    np.testing.assert_array_equal(together.K[0], apart.K[0])
    assert together.params == apart.params
    assert together.observer.why == apart.observer.why == "set by the user"
