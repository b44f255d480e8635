"""Where a failed assumption is the sector model's form, not the plant (fte_casadi/design/_model_form.py): a
chemostat in absolute units (tests/plant_chemostat.py) has the substrate's whole effect held in premises and in
the input's coefficient, every A_i's column of S zero, so the rank tests refuse a probe fault on a measured
state; and a plant whose model about x = 0 misses most of its linear motion at the reference is warned."""

import numpy as np
import pytest
from plant_chemostat import chemostat, chemostat_deviations, chemostat_probe

from fte_casadi.design import design
from fte_casadi.design._model_form import MISSED, hidden_effects, missed_motion, reference_point
from fte_casadi.errors import AssumptionError
from fte_casadi.ts import derive


@pytest.fixture(scope="module")
def probe():
    return derive(chemostat_probe(), fidelity_samples=200)


def test_the_hidden_states_are_those_the_plant_moves_with_and_no_A_i_does(probe):
    h = hidden_effects(probe)
    assert h is not None and [probe.plant.state_names[k] for k in h.states] == ["S", "P"]
    for k in h.states:  # the model: a zero column in every rule; the plant at its reference: not
        assert all(np.all(lm.A[:, k] == 0.0) for lm in probe.local_models)
        assert np.linalg.norm(h.jacobian[:, k]) > 0.1
    # the point: the reference state, and the dilution rate that holds it (mu(S0) = 0.3 per h)
    x_star, u_star = reference_point(probe.plant)
    assert np.allclose(x_star, probe.plant.x_ref) and u_star == pytest.approx([0.3], rel=1e-9)
    # the advice checked: written in deviations, assumption (2) holds in every rule of the model derived again
    failed, rules = h.in_deviations
    assert failed == 0 and rules > 1
    assert "(checked: the plant so written derives a model for which assumption (2) holds" in h.render(
        probe.plant
    )


def test_with_both_faults_the_check_says_the_faults_themselves_act_alike():
    h = hidden_effects(derive(chemostat(), fidelity_samples=200))
    failed, rules = h.in_deviations
    assert 0 < failed < rules
    text = h.render(chemostat())
    assert f"still fails in {failed} of its {rules} rules, for another reason" in text
    assert text.startswith(
        "the model's form may be part of the cause"
    )  # not "the cause": the check says otherwise


def test_the_refusal_names_the_models_form_and_its_advice(probe):
    with pytest.raises(AssumptionError) as info:
        design(probe)
    text = " ".join(str(info.value).split())
    assert "assumption (2) fails" in text and "But the model's form is the cause, not the plant" in text
    assert 'the columns of "S", "P" are zero in every A_i' in text
    assert "b.operating_point(u=[0.3])" in text and "X - 4.846, S - 0.3071, P - 10.5" in text


def test_a_refusal_by_the_lmis_says_the_model_is_off_at_the_reference(probe):
    """Assumptions (2) and (4) accepted, (45) refuses the chemostat: the refusal says that its model about x = 0 is off
    at the reference, with the advice."""
    from fte_casadi.errors import InfeasibleDesignError

    with pytest.raises(InfeasibleDesignError) as info:
        design(probe, accept_assumptions=["(2)", "(4)"])
    text = " ".join(str(info.value).split())
    assert (
        "LMI (45)" in text and "is off by 1.1 in the rate of X (its row of df/dx there: [0, 1.81, 0]" in text
    )
    assert "Write the plant in deviations from its reference (X - 4.846" in text


def test_a_plant_in_deviations_hides_nothing_and_is_not_warned():
    ts = derive(chemostat_deviations(), fidelity_samples=200)
    assert hidden_effects(ts) is None and missed_motion(ts) is None


def test_the_model_about_zero_missing_the_motion_at_the_reference_is_warned(probe):
    share, text = missed_motion(probe)
    assert MISSED < share <= 2.0  # ||J_i - A_i|| over the larger of the two rows: at most 2
    assert text.startswith("warning: the T-S model is written about x = 0")
    assert f"is off by {share:.2g} in the rate of X" in text
    assert "(X - 4.846, S - 0.3071, P - 10.5; the inputs less [0.3]" in text


def test_fte_derive_warns_on_stderr_and_not_for_the_deviation_form():
    from click.testing import CliRunner

    from fte_casadi.cli import main

    here = __import__("pathlib").Path(__file__).resolve().parent / "plant_chemostat.py"
    r = CliRunner().invoke(main, ["derive", f"{here}:chemostat_probe"])
    assert r.exit_code == 0, r.output
    said = " ".join(r.stderr.split())
    assert (
        "fte: warning: the T-S model is written about x = 0" in said
        and "is off by 1.1 in the rate of X" in said
    )
    assert "warning" not in r.stdout  # the model itself on stdout, unchanged
    quiet = CliRunner().invoke(main, ["derive", f"{here}:chemostat_deviations"])
    assert quiet.exit_code == 0 and "warning" not in quiet.stderr


def test_the_share_missed_is_the_reference_inputs_part_of_the_jacobian():
    """x' = A x + (b + N x) u at the reference input u0 (x* = 0): the plant's df/dx there is A + N u0, the model's A
    about x = 0 is A (N x u is the input's coefficient), so each state's share missed is ||(N u0)_i|| /
    max(||(A + N u0)_i||, ||A_i||) (the region's half-widths are 1), warned above MISSED at the largest; a linear
    plant (N = 0) misses nothing wherever it rests."""
    from hypothesis import assume, given, settings
    from hypothesis import strategies as st

    from fte_casadi import PlantBuilder

    entry = st.floats(-2.0, 2.0).map(lambda v: round(v, 3))

    @settings(max_examples=15, deadline=None)
    @given(a=st.lists(entry, min_size=4, max_size=4), n=st.lists(entry, min_size=4, max_size=4),
           u0=st.floats(-3.0, 3.0).map(lambda v: round(v, 3)), linear=st.booleans())  # fmt: skip
    def check(a, n, u0, linear):
        A, N = np.reshape(a, (2, 2)), np.zeros((2, 2)) if linear else np.reshape(n, (2, 2))
        b = PlantBuilder("bilinear")
        x1, x2 = b.states("x1", "x2")
        (u,) = b.inputs("u")
        (fa,) = b.faults("fa", kind="actuator")
        (fs,) = b.faults("fs", kind="sensor")
        x = [x1, x2]
        coef = [1.0 + N[i, 0] * x1 + N[i, 1] * x2 for i in range(2)]
        b.drift([A[i, 0] * x1 + A[i, 1] * x2 + coef[i] * (u + fa) for i in range(2)])
        b.outputs([x[0] + fs, x[1], x[0] + x[1]])
        b.region(x1=(-1.0, 1.0), x2=(-1.0, 1.0))
        b.reference(u=[u0])
        J = A + N * u0
        found = missed_motion(derive(b.build(), fidelity_samples=50))
        den = np.maximum(np.linalg.norm(J, axis=1), np.linalg.norm(A, axis=1))
        shares = [np.linalg.norm((N * u0)[i]) / den[i] for i in range(2) if den[i] > 0]
        share = max(shares, default=0.0)
        assume(abs(share - MISSED) > 1e-9)  # at the threshold itself the last bit decides
        assert (found is not None) == (share > MISSED)
        if found is not None:
            assert found[0] == pytest.approx(share, rel=1e-9, abs=1e-12)

    check()


def test_the_share_does_not_depend_on_the_states_units():
    """The generator's angle in degrees and its speed in mpu (x 57.3 and x 1000, the region too) misses the same share
    of the speed's rate as in rad and pu: each state's column is weighted by its half-width in the region."""
    from plant_smib import smib

    base = missed_motion(derive(smib(), fidelity_samples=50))
    scaled = missed_motion(
        derive(smib(angle_per_rad=180.0 / np.pi, speed_per_pu=1000.0), fidelity_samples=50)
    )
    assert base[0] > MISSED and scaled[0] == pytest.approx(base[0], rel=1e-9)


def test_a_reference_outside_the_region_is_left_alone():
    """The model claims nothing outside its region, where the plant need not even be finite (sqrt(x1) at x1 = -1):
    no warning, no diagnosis, no crash (review: `fte derive` died with an internal LinAlgError)."""
    import casadi as ca

    from fte_casadi import PlantBuilder

    b = PlantBuilder("outside")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([x2, -x1 - x2 + (u + fa) * ca.sqrt(x1)])
    b.outputs([x1 + fs, x2, x1 + x2])
    b.region(x1=(1.0, 4.0), x2=(-1.0, 1.0))
    b.reference(x=[-1.0, 0.0])
    ts = derive(b.build(), fidelity_samples=50)
    assert reference_point(ts.plant) is None and missed_motion(ts) is None and hidden_effects(ts) is None
