"""Issue #21 item 4: a loss of effectiveness scales the input the actuator delivers."""

from __future__ import annotations

import numpy as np
import pytest
from plant_deviation import plain, plant, scenario

from fte_casadi.design import design
from fte_casadi.errors import FteError
from fte_casadi.sim import simulate
from fte_casadi.sim._engine import plant_schedule
from fte_casadi.ts import derive


@pytest.fixture(scope="module")
def deviation_design():
    p = plant()
    return p, design(derive(p), sigma=0.5, sample_time=scenario().dt)


def test_loss_scales_the_operating_point_plus_the_deviation(deviation_design):
    p, d = deviation_design
    sc = scenario()
    t = np.arange(0, 4.0 + 1e-12, sc.dt)
    sched = plant_schedule(d, p, sc, t, sc.dt)
    on = (t >= 1.0) & (t < 3.0 - 1e-12)
    # fa = -0.3 (3 + u): the operating point's part is additive, the deviation's part scales u
    np.testing.assert_allclose(sched.a[on, 0], -0.3 * 3.0)
    np.testing.assert_allclose(sched.lu[on, 0], -0.3)
    assert not np.any(sched.a[~on, 0]) and not np.any(sched.lu[~on, 0])


def test_the_loss_is_seen_and_compensated(deviation_design):
    p, d = deviation_design
    m = simulate(d, p, scenario(), paths=4, seed=1, progress=False).metrics
    assert m["fault_rel_rms_error"][0] < 0.3  # the estimate follows a fault of about -0.9
    assert m["ftc_true_ratio"] < 0.5  # tolerant control removes most of its effect


@pytest.mark.slow
def test_a_loss_that_would_do_nothing_is_refused():
    p = plain()
    d = design(derive(p), sigma=0.5, sample_time=scenario().dt)
    with pytest.raises(FteError, match=r"zero at rest.*operating_point\(u=\[\.\.\.\]\)"):
        simulate(d, p, scenario(), paths=1, seed=1, progress=False)
