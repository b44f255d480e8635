"""The scalable chain family (issue #17), designed at its defaults: no design defaults, so the tool
finds its own parameters; every member certified, whatever the BLAS's thread count. The members here run
from 2 to 8 states and from 2 to 64 rules; `fte bench` designs the larger ones (docs/benchmarks.md)."""

from __future__ import annotations

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from fte_casadi.bench._plant_chain import chain
from fte_casadi.design import design
from fte_casadi.design.core._certify import failures
from fte_casadi.ts import derive


@pytest.mark.slow
# the 16- and 24-state members (1-2.5 minutes each here) are designed and certified by `fte bench`'s family
# (README's size table, docs/benchmarks.md), not again by the suite
# 64 rules (6, 6) repeats (6, 4)'s property on four times the rules: left to `pytest -m heavy`, as the 64-rule chain
@pytest.mark.parametrize(
    ("n", "q"), [(2, 1), (4, 2), (8, 2), (6, 4), pytest.param(6, 6, marks=pytest.mark.heavy)]
)
def test_a_member_designs_at_its_defaults(n, q):
    ts = derive(chain(n, q), fidelity_samples=500)
    assert ts.r == 2**q and not chain(n, q).design_defaults
    d = design(ts, sample_time=1e-3)
    assert d.certified and not failures(d.checks)
    assert d.checks["discrete"]["holds"]
    # the parameters are the generic ones or ones the tool chose and recorded with why
    for k, c in (d.params_chosen or {}).items():
        assert getattr(d.params, k) == c["value"] and "certified design" in c["why"]


@pytest.mark.slow
def test_the_design_limits_the_blas_to_one_thread(monkeypatch):
    """design() runs under threadpoolctl's limit of one BLAS thread (small dense algebra thrashes in many)."""
    seen = []
    from fte_casadi.design.core import _conditioned as conditioned

    step3 = conditioned.step3

    def spy(*a, **k):
        seen.extend(i["num_threads"] for i in threadpool_info() if i.get("user_api") == "blas")
        return step3(*a, **k)

    monkeypatch.setattr(conditioned, "step3", spy)
    design(derive(chain(2, 1), fidelity_samples=200), sample_time=1e-3)
    assert seen and all(t == 1 for t in seen)


@pytest.mark.slow
def test_the_numpy_starts_and_the_rule_subsets_do_not_change_the_design(monkeypatch):
    """A heavy problem's step 3 starts from phase 1 in numpy instead of a conic solve, and step 5's
    decisions in alpha take the rules a few at a time (barrier.phase1_active); both only change the path
    to the design, not the design: a 16-rule member designed with every start from the conic solver and
    every decision on all rules, and with every problem treated as heavy and subsets of 2 rules, gives the
    same alpha and the same Pbar and K to round-off."""
    from fte_casadi.design.core import _barrier as barrier
    from fte_casadi.design.core import _sdp as sdp

    ts = derive(chain(4, 4), fidelity_samples=300)
    out = []
    for heavy, add in ((10**9, 10**6), (0, 2)):
        monkeypatch.setattr(sdp, "HEAVY_CONES", heavy)
        monkeypatch.setattr(barrier, "ACTIVE_ADD", add)
        d = design(ts, sample_time=1e-3, sigma=0.47, gamma=1.0)
        assert d.certified
        out.append(d)
    a, b = out
    notes = " ".join(b.status)
    assert "step 3: phase 1 in numpy gave this answer (a point" in notes
    assert "phase 1 in numpy" not in " ".join(a.status)
    assert a.observer.alpha == pytest.approx(b.observer.alpha, rel=1e-9)
    for x, y in ((a.Pbar, b.Pbar), (a.K[0], b.K[0])):
        x, y = np.asarray(x), np.asarray(y)
        assert np.max(np.abs(x - y)) <= 1e-7 * np.max(np.abs(x))
