"""A state measured in units far from its range (tests/plant_maglev_noisy.py: the gap in m, 1e-3 wide, beside the
current in A) must not turn the bounds' margins and caps into a false "infeasible": the largest sigma (45) allows
is found, not "no sigma > 0", and where (45) holds only with cond(X) above the default bound, step 3 raises kappa
and says so."""

from __future__ import annotations

import numpy as np
import pytest
from plant_maglev_noisy import maglev

from fte_casadi.design import DesignOptions, augment
from fte_casadi.design import _pipeline as pipeline
from fte_casadi.design._options import resolve
from fte_casadi.design.core import _conditioned as conditioned
from fte_casadi.design.core._diagnose import sigma_max
from fte_casadi.design.diagnose._explain import _kappa_binds
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive


@pytest.fixture(scope="module")
def ts():
    return derive(maglev(), fidelity_samples=200)


def test_the_largest_sigma_is_found_for_a_gap_in_metres(ts):
    """At the margin X >= 1e-3 I every X of this plant is excluded (X's smallest eigenvalue is ~5e-5 m^2 at the
    bound); the bound was "no sigma > 0". A smaller margin finds it, and (45) holds just below it and not above."""
    aug = augment(ts.local_models, ts.C, ts.Df)
    smax, status = sigma_max.__wrapped__(aug, 1.0, 0.5, "CLARABEL")
    assert status == "optimal" and smax is not None and 1e-3 < smax < 1.0
    params = {"gamma": 1.0, "gamma1": 0.5, "delta": 1e-4, "epsilon": 1e-4, "kappa": 1e10}
    s3 = conditioned.step3(aug, dict(params, sigma=0.9 * smax), "CLARABEL")  # feasible below the bound ...
    assert np.all(np.linalg.eigvalsh(s3.X) > 0)
    with pytest.raises(InfeasibleDesignError):  # ... and not above it
        conditioned.step3(aug, dict(params, sigma=1.2 * smax), "CLARABEL")


def test_step3_raises_kappa_where_the_default_bound_binds(ts):
    """Below sigma_max, (45) needs cond(X) ~ 7e6 here: under the default bound 1e4 it is infeasible; step 3 tries
    the larger bounds, keeps the first that works, says so, and the observer is designed under the same kappa."""
    opts = DesignOptions(sigma=0.015)
    res = resolve(ts, opts)
    st = pipeline.structure(ts, opts, res)
    with pytest.raises(InfeasibleDesignError):
        conditioned.step3(st.aug, res.params, "CLARABEL")
    s3 = pipeline.step3(st, res, "CLARABEL")
    assert s3.kappa > conditioned.KAPPA and s3.kappa in pipeline.KAPPA_LADDER
    assert np.linalg.cond(s3.X) > conditioned.KAPPA
    assert any(f"kappa = {s3.kappa:g}" in n and "the bound binds" in n for n in s3.notes)
    assert pipeline.params_of(res, s3)["kappa"] == s3.kappa
    # the refusal at the defaults names it too (the parameter search's trials do not search kappa): at 0.8 x the
    # largest sigma, feasible only above the default bound, under 1e7
    smax, _ = sigma_max(st.aug, res.params["gamma"], res.params["gamma1"], "CLARABEL")
    sg, kappa = _kappa_binds(st.aug, dict(res.params, sigma=1.0), smax, "CLARABEL")
    assert sg == 0.015 < smax and kappa == s3.kappa  # 0.8 x 0.0193, rounded down: the sigma step 3 had above
    assert (
        _kappa_binds(st.aug, dict(res.params, kappa=1e4), smax, "CLARABEL") is None
    )  # a kappa given: not named
    # a kappa given is kept: no search
    res_k = resolve(ts, DesignOptions(sigma=0.015, kappa=1e4))
    with pytest.raises(InfeasibleDesignError):
        pipeline.step3(st, res_k, "CLARABEL")
