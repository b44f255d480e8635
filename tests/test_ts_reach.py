"""Modes at the origin that no feedback of the model reaches (fte_casadi/ts/_reach.py): named by derive, with the
input coefficients that vanish there; none for a plant whose inputs act at the origin."""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest
from plant_auto import two_state

from fte_casadi.design import design
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive


def test_an_input_acting_through_a_state_is_named_and_no_design_exists():
    """x2' = -x2 + x1 (u + fa): at x1 = 0 the input does not act, and x1' = x2 leaves x1 an integrator; the
    note names the mode and B[x2, u], and the design is indeed refused."""
    ts = derive(two_state(lambda x1, x2, u, fa: [x2, -x2 + x1 * (u + fa)]), fidelity_samples=500)
    notes = [n for n in ts.notes if n.startswith("at the origin")]
    assert len(notes) == 1 and "the mode s = 0 of x1:" in notes[0] and "B[x2, u] is 0 there" in notes[0]
    with pytest.raises(InfeasibleDesignError, match=r"\(45\)"):
        design(ts, sample_time=1e-3, diagnose=False)


def test_inputs_that_act_at_the_origin_give_no_note():
    ts = derive(two_state(lambda x1, x2, u, fa: [x2, -ca.sin(x1) - x2 + (1 + 0.5 * x1**2) * (u + fa)]),
                fidelity_samples=500)  # fmt: skip
    assert not [n for n in ts.notes if n.startswith("at the origin")]
    assert np.all([abs(lm.B[1, 0]) > 0 for lm in ts.local_models])
