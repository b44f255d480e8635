"""The refusal record (fte_casadi/errors.py): the message is rendered from it, it survives a pickle, and the
design decides on its fields, never on its words."""

from __future__ import annotations

import pickle

import pytest

from fte_casadi.design import _pipeline as pipeline
from fte_casadi.design import design, diagnose
from fte_casadi.errors import InfeasibleDesignError, Refusal, Refused, SolverFailedError
from fte_casadi.plants import manipulator
from fte_casadi.ts import derive


class _Found:
    def render(self) -> str:
        return "the plant's diffusion is the cause: 20 % of it"


def test_a_refusal_is_rendered_from_its_parts():
    bare = Refusal(
        Refused.LMI, "LMI (46) with cond(Pbar) <= 1e+04 is infeasible (CLARABEL: infeasible); its block"
    )
    assert bare.render() == bare.statement  # a statement alone is the message, as written
    tried = (
        ({"sigma": 0.4}, "LMI (45) is   infeasible"),
        ({"sigma": 0.2, "gamma": 3.0}, "no certified design"),
    )
    r = Refusal(Refused.LMI, "LMI (45) is infeasible: a; b.", lmi="45", detail="The block must dominate",
                advice="no value tried gives a certified design", tried=tried)  # fmt: skip
    assert r.render() == (
        "LMI (45) is infeasible: a; b. The block must dominate. No value tried gives a certified design. The values "
        "tried were refused for other reasons: at sigma = 0.4: LMI (45) is infeasible; at sigma = 0.2, gamma = 3: "
        "no certified design."
    )
    # a cause found replaces advice that was not checked; the values tried stay, before it (the search may have
    # passed the statement's LMI and stopped at another)
    found = Refusal(
        Refused.LMI, "LMI (45) is infeasible: a", advice="no value tried", tried=tried, found=_Found()
    )
    assert found.render() == (
        "LMI (45) is infeasible: a. The values tried were refused for other reasons: at sigma = 0.4: LMI (45) is "
        "infeasible; at sigma = 0.2, gamma = 3: no certified design. The plant's diffusion is the cause: 20 % of it."
    )
    # a checked advice stays beside it
    checked = Refusal(Refused.LMI, "LMI (45) is infeasible: a", advice="lower sigma to <= 0.1 (checked)",
                      checked=True, tried=tried, found=_Found())  # fmt: skip
    assert checked.render() == (
        "LMI (45) is infeasible: a. Lower sigma to <= 0.1 (checked). The plant's diffusion is the cause: 20 % of it."
    )


def test_the_error_carries_its_record_also_through_a_pickle():
    exc = InfeasibleDesignError("step 5 at alpha = 3 is infeasible", kind=Refused.DECAY_RATE, lmi="46",
                                numbers={"alpha": 3.0})  # fmt: skip
    assert str(exc) == "step 5 at alpha = 3 is infeasible" and exc.lmi == "46" and not exc.bounded
    back = pickle.loads(pickle.dumps(exc))
    assert back.refusal == exc.refusal and str(back) == str(exc) and back.refusal.numbers == {"alpha": 3.0}
    failed = pickle.loads(pickle.dumps(SolverFailedError("step 3 failed", lmi="45", solver_independent=True)))
    assert failed.lmi == "45" and failed.solver_independent and str(failed) == "step 3 failed"


@pytest.fixture(scope="module")
def ts():
    return derive(manipulator(), fidelity_samples=200)


@pytest.mark.parametrize(
    ("kind", "words", "diagnosed"),
    [
        (
            Refused.LMI,
            "the observer decay rate alpha at the sample time",
            True,
        ),  # the old test read these words
        (Refused.DECAY_RATE, "LMI (46) is infeasible", False),
        (Refused.SAMPLE_TIME, "LMI (46) is infeasible", False),
        (Refused.SETTLE, "LMI (46) is infeasible", False),
    ],
)
def test_the_design_decides_on_the_refusals_kind_not_its_words(ts, monkeypatch, kind, words, diagnosed):
    """A step-5 refusal goes to the diagnosis (the parameter search first) unless it refuses what was asked for (a
    decay rate, a sample time, a settling window), whatever its message says."""
    asked = []

    def refuse(*args, **kwargs):
        raise InfeasibleDesignError(words, kind=kind, lmi="46")

    class Searched(Exception):
        pass

    def search(*args, **kwargs):
        asked.append(args[6])  # the LMI the search is for
        raise Searched

    monkeypatch.setattr(pipeline, "loop_then_observer", refuse)
    monkeypatch.setattr(diagnose, "choose", search)
    with pytest.raises(Searched if diagnosed else InfeasibleDesignError):
        design(ts, sample_time=1e-3)
    assert asked == (["46"] if diagnosed else [])
