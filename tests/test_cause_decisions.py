"""A refusal's cause is a decision about the LMIs, never a solver's failure read as one: a numerical failure
leaves the fault-separability claim unmade, and the causes are decided with the interior-point solver
whichever solver the design asked for (SCS's first-order answers had named a fault of the flexible joint
instead of its diffusion)."""

from __future__ import annotations

import pytest
from plant_twin_fans import fans_alike

from fte_casadi.design import diagnose
from fte_casadi.design.core import _conditioned as conditioned
from fte_casadi.design.diagnose import _separability as separability
from fte_casadi.design.diagnose import blocking
from fte_casadi.ts import derive

pytestmark = pytest.mark.slow  # a design with SCS: 45 s

PARAMS = dict(sigma=0.0062, gamma=16.0997, gamma1=2.23607, delta=1e-4, epsilon=1e-4)


@pytest.fixture(scope="module")
def fans():
    return derive(fans_alike(), fidelity_samples=300)


def test_a_numerical_failure_is_no_claim_that_a_fault_blocks(fans, monkeypatch):
    assert [b.name for b in blocking(fans, PARAMS, "CLARABEL")] == ["fan1_loss", "fan2_loss"]

    def failing(*args, **kwargs):
        raise conditioned.SolverFailedError("a numerical failure")

    monkeypatch.setattr(conditioned, "step3", failing)
    assert blocking(fans, PARAMS, "CLARABEL") == []


def test_the_causes_are_decided_with_clarabel_when_scs_designs(fans, monkeypatch):
    """A refusal's causes are decided with Clarabel whatever solver designs: the naming functions a refusal calls
    (diagnose.name_cause -> weak_faults, blocking_diffusion) take no solver, and ask Clarabel. Called here as a
    refusal with SCS calls them (the whole refused design with SCS, 3.5 minutes on 2 cores, is not run again:
    test_explore_names_the_faults_when_no_sigma_gives_a_design below names the same faults end to end)."""
    import inspect

    from fte_casadi.design.diagnose import _naming as naming

    for f in (naming.weak_faults, naming.blocking_diffusion):
        assert "solver" not in inspect.signature(f).parameters
    asked = []
    real = separability.blocking

    def spy(ts, params, solver):
        asked.append(solver)
        return real(ts, params, solver)

    monkeypatch.setattr(separability, "blocking", spy)
    where = {k: PARAMS[k] for k in ("sigma", "gamma", "gamma1")}
    found = naming.weak_faults(fans, PARAMS, where)
    assert found is not None and "'fan1_loss', 'fan2_loss' are the cause" in " ".join(found.render().split())
    assert asked and set(asked) == {diagnose.DECIDING_SOLVER} == {"CLARABEL"}


def test_explore_names_the_faults_when_no_sigma_gives_a_design(fans):
    from fte_casadi.design import explore

    _, info = explore(
        fans, count=2
    )  # two sigmas across the range: neither gives a design (none of the default 12)
    assert info["best"] is None
    assert "the faults 'fan1_loss', 'fan2_loss' are the cause" in info["cause"]
    assert "(checked)" in info["cause"]
