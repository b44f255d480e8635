"""A 12-state quadrotor written as a user writes it (tests/plant_quadrotor.py: Newton-Euler, ZYX Euler angles, SI
units, thrust and three torques): its premises found automatically, the groups of nested states covered together
(fte_casadi/ts/_cover.py), 64 rules or fewer, and the model exact at random states of the region."""

from __future__ import annotations

import numpy as np
import pytest
from plant_quadrotor import quadrotor

from fte_casadi.ts import derive
from fte_casadi.ts._cover import MERGE_ABOVE, plan_groups
from fte_casadi.ts._fidelity import blended, sample_box

pytestmark = pytest.mark.slow

EXACT = 1e-9  # relative to each row's size, as the automatic method's own check (auto_checks.EXACT_TOL)


@pytest.fixture(scope="module")
def quad():
    """The derivation, and the work it did: local searches and their evaluations, of the premises' bounds and of
    the simplices' normals (counted, not timed)."""
    import fte_casadi.ts._cover as cover_mod
    import fte_casadi.ts._premise_bounds as bounds_mod

    work = {"bounds": [0, 0], "cover": [0, 0]}

    def counting(key, minimize):
        def run(*args, **kwargs):
            res = minimize(*args, **kwargs)
            work[key][0] += 1
            work[key][1] += int(res.nfev)
            return res

        return run

    with pytest.MonkeyPatch.context() as mp:
        mp.setattr(bounds_mod, "minimize", counting("bounds", bounds_mod.minimize))
        mp.setattr(cover_mod, "minimize", counting("cover", cover_mod.minimize))
        with pytest.warns(RuntimeWarning, match="found 10 premises"):
            ts = derive(quadrotor(), fidelity_samples=2000)
    return ts, work


def test_quadrotor_derives_to_64_rules_or_fewer(quad):
    ts, work = quad
    assert ts.kind == "sector_auto" and len(ts.premises) == 10
    # the kinematics telescoped with the angles first: each premise a function of the angles alone, but one
    states = ts.plant.state_names
    on = [tuple(states[j] for j in p.states) for p in ts.premises]
    assert sorted(set(on)) == [("phi",), ("phi", "theta"), ("phi", "theta", "psi"), ("r",)]
    # one group per set of states would be 3 x 6 x 3 x 2 = 108 rules: roll's group joins roll and pitch's
    assert np.prod([len(g) + 1 if len(g) > 1 else 2 for g in plan_groups([p.states for p in ts.premises],
                                                                       merge=False)]) == 108  # fmt: skip
    assert [sorted(states[j] for j in g.states) for g in ts.groups] == [["phi", "psi", "theta"], ["phi", "theta"],
                                                                      ["r"]]  # fmt: skip
    assert ts.r == 48 <= MERGE_ABOVE and ts.r == int(np.prod([len(g.vertices) for g in ts.groups]))
    assert [p.expr for p in ts.premises if p.states == (6,)] == ["cos(phi)", "sin(phi)"]
    # with the total thrust as the input, the tilt acts on vx, vy only through the thrust's coefficients, 0 at
    # hover: derive says that no design exists, and why (tests/test_ts_reach.py checks such a refusal)
    (note,) = [n for n in ts.notes if n.startswith("at the origin")]
    assert "the mode s = 0 of px, py:" in note and "B[vx, thrust], B[vy, thrust] are 0 there" in note
    # the work (measured: 1693 bound searches, 6220 evaluations; 6 normal searches, 7643 evaluations). The
    # 7-dimensional simplex searched from five starts over all its normals, as the smaller ones are, would take
    # up to 140 000 evaluations (minutes)
    assert work["bounds"][0] <= 2500 and work["bounds"][1] <= 10_000
    assert work["cover"][0] <= 6 and work["cover"][1] <= 12_000


def test_quadrotor_model_is_exact_at_random_states(quad):
    ts, _ = quad
    plant = ts.plant
    rng = np.random.default_rng(11)
    s = sample_box(plant, 3000, rng)
    true = np.array(plant.drift_function().map(3000)(s["x"], s["u"], s["d"], s["f"]))
    true_g = np.array(plant.diffusion_function().map(3000)(s["x"], s["u"], s["f"], s["d2"]))
    bf, bg = blended(ts, s["x"], s["u"], s["d"], s["f"], s["d2"])
    scale = np.maximum(np.max(np.abs(true), axis=1), np.max(np.abs(true_g), axis=1))
    assert np.all(np.max(np.abs(true - bf), axis=1) <= EXACT * scale)
    assert np.all(np.max(np.abs(true_g - bg), axis=1) <= EXACT * scale)
    # the memberships are a convex sum that reproduces the premises (the reason the blend is exact)
    H = ts.memberships(s["x"])
    Z = np.array(ts.premise_fn.map(3000)(s["x"])).reshape(len(ts.premises), -1)
    assert H.min() >= -1e-12 and np.max(np.abs(H.sum(axis=0) - 1)) <= 1e-12
    assert np.max(np.abs(ts.rule_premises.T @ H - Z)) <= 1e-9
    # the model's own checks: fidelity over the region at round-off (derive refuses an inexact one)
    assert ts.fidelity.drift_max_rel_error <= EXACT and ts.fidelity.max_abs_error <= 1e-11
