"""A slow plant measured in small units (issue #17's "real plants"): time constants of 100-130 s, an input
gain of 1e-3, every level measured in mm of a state in m (outputs x 1e3), 4 rules, no design defaults.

(45) then needs sigma of order 1e-11 and gamma of order 50: four orders of magnitude from any default. The
bounds, posed in the plant's own time and output size, find them; at a sample time of 1 s no certified
observer exists (its fastest mode is ~5e3 /s) and the refusal says so and names the sample time that works,
which then certifies."""

from __future__ import annotations

import re

import casadi as ca
import pytest

from fte_casadi import PlantBuilder
from fte_casadi.design import design
from fte_casadi.design.augment import augment
from fte_casadi.design.diagnose import sigma_max
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive


def slow_plant(n: int = 4, q: int = 2):
    b = PlantBuilder(f"slow{n}")
    x = b.states(*[f"x{k + 1}" for k in range(n)])
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    rates = []
    for k in range(n):
        c = 0.008 * ca.sin(x[k - 1]) if k < q else 0.008 * x[k - 1]
        r = -x[k] / (100.0 + 10.0 * k) + (0.25 * c if k == 0 else c)
        if k == 0:
            r += 1e-3 * (u + fa) + 5e-4 * d
        if k == n - 1:
            r += 3e-4 * d
        rates.append(r)
    b.drift(rates)
    b.diffusion([1e-4 * xk for xk in x])
    b.outputs([1e3 * x[0] + fs] + [1e3 * xk for xk in x])
    b.region(**{f"x{k + 1}": (-1.0, 1.0) for k in range(n)})
    return b.build()


@pytest.fixture(scope="module")
def ts():
    return derive(slow_plant(), fidelity_samples=300)


def test_the_bounds_find_a_sigma_four_orders_below_the_defaults(ts):
    aug = augment(ts.local_models, ts.C, ts.Df)
    sup, status = sigma_max(aug, None, 0.5, "CLARABEL")
    assert sup is not None and 1e-13 < sup < 1e-9, (sup, status)


def test_the_refusal_names_the_sample_time_and_that_one_certifies(ts):
    with pytest.raises(InfeasibleDesignError) as exc:
        design(ts, sample_time=1.0)
    msg = " ".join(str(exc.value).split())
    assert "refused for other reasons" in msg and "no certified design runs at the sample time 1" in msg
    ts_ok = float(re.search(r"sample time <= ([0-9.e+-]+)", msg).group(1))
    assert 1e-5 < ts_ok < 1e-2
    d = design(ts, sample_time=ts_ok)
    assert d.certified and d.checks["discrete"]["holds"]
    assert d.params["sigma"] < 1e-9 and set(d.params_chosen) == {"sigma", "gamma"}


def test_an_unstable_mode_barely_reachable_is_named(ts):
    """Coupled more strongly than it decays, the chain is open-loop unstable and its one input, at the chain's
    head, reaches the unstable modes only weakly: the reason (45) may leave no margin sigma at all."""
    from fte_casadi.design.limits import reachability

    assert reachability(augment(ts.local_models, ts.C, ts.Df)) == ""  # the 4-stage chain is stable
    long_chain = derive(slow_plant(16, 4), fidelity_samples=200)
    why = reachability(augment(long_chain.local_models, long_chain.C, long_chain.Df))
    assert "open loop is unstable" in why
    pbh = float(re.search(r"\|\| = ([0-9.e+-]+)", why).group(1))
    assert 0 < pbh < 0.05
