"""Automatic premises in any units (fte_casadi/ts/_auto.py, _auto_checks.py, _premise_bounds.py): every tolerance of the
automatic sector method is relative to the size of what it compares, so a plant written in m and in mm derives,
and to the same model after the change of unit."""

from __future__ import annotations

import numpy as np
import pytest
from plant_maglev import maglev_m, maglev_mm
from tolerances import ROUNDOFF

from fte_casadi.ts import derive
from fte_casadi.ts._auto_checks import TAYLOR_BAND, state_scale

#: gap and velocity in mm and mm/s instead of m and m/s; the current in A in both
T = np.diag([1e3, 1e3, 1.0])
#: the faults: the voltage's in V in both, the gap sensor's in mm instead of m
T_F = np.diag([1.0, 1e3])


@pytest.fixture(scope="module")
def both():
    return derive(maglev_m(), fidelity_samples=4000), derive(maglev_mm(), fidelity_samples=4000)


def test_maglev_in_metres_derives_exactly(both):
    """The gap in metres (3-9 mm) was refused: a Taylor band of an absolute 1e-4 is 0.1 mm there, a third of
    the gap's range, and the coefficient of the gap was wrong by 8.4e-6 m/s^2 at gap_dev = -1e-4 m. In the
    gap's own scale the band is 3e-7 m."""
    m, _ = both
    assert m.r == 4 and len(m.premises) == 2 and m.kind == "sector_auto"
    assert m.fidelity.drift_max_rel_error <= ROUNDOFF
    assert TAYLOR_BAND * state_scale(*m.plant.region_lo[:1], *m.plant.region_hi[:1]) == pytest.approx(3e-7)
    # at the old band's edge, where the model was wrong, and at the new one's: exact to round-off
    x = np.array([[-1e-4, 1e-4, -3e-7, 3e-7, 0.0], [0.01] * 5, [0.4, -0.4, 0.3, -0.3, 0.2]])
    h = m.memberships(x)
    true = np.array(m.plant.drift_function().map(5)(x, np.zeros((1, 5)), np.zeros((1, 5)), np.zeros((2, 5))))
    blended = sum(h[i] * (lm.A @ x + lm.a[:, None]) for i, lm in enumerate(m.local_models))
    assert np.max(np.abs(true - blended)[1]) <= 1e-12 * np.max(np.abs(true[1]))


def test_maglev_in_metres_and_in_millimetres_gets_the_same_model(both):
    m, mm = both
    assert m.r == mm.r and [len(g.vertices) for g in m.groups] == [len(g.vertices) for g in mm.groups]
    Ti = np.linalg.inv(T)
    worst = 0.0
    # the same rules in the same order, after the unit change
    for a, b in zip(m.local_models, mm.local_models):
        for x, y in ((T @ a.A @ Ti, b.A), (T @ a.B, b.B), (T @ a.Bd, b.Bd), (T @ a.Bf @ np.linalg.inv(T_F), b.Bf),
                     (T @ a.W @ Ti, b.W), (T @ a.a, b.a)):  # fmt: skip
            worst = max(worst, float(np.max(np.abs(x - y), initial=0.0) / max(np.max(np.abs(y)), 1.0)))
    assert worst <= 1e-12
    # premises: the same functions up to a constant factor (the unit of their coefficient), the same rules
    for pa, pb in zip(m.premises, mm.premises):
        k = pb.max / pa.max
        assert pb.min == pytest.approx(k * pa.min, rel=1e-12) and k > 0
    np.testing.assert_allclose(T @ m.C @ Ti, mm.C, rtol=0, atol=0)
    np.testing.assert_allclose(T @ m.Df @ np.linalg.inv(T_F), mm.Df, rtol=0, atol=0)
    # no offset in either: g - k i0^2 / (m x0^2) is 0 in m, and round-off (-1.8e-12) in mm, not an offset
    assert not any(np.any(lm.a) for lm in m.local_models + mm.local_models)
    assert not any("offset" in n for n in m.notes + mm.notes)


def test_state_scale():
    assert state_scale(-3e-3, 3e-3) == 3e-3 and state_scale(-1.0, 2.0) == 2.0
    assert state_scale(0.0, 0.0) == 1.0 and state_scale(np.nan, np.nan) == 1.0
