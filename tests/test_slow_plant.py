"""A slow plant measured in small units (issue #17's "real plants"): time constants of 100-130 s, an input
gain of 1e-3, every level measured in mm of a state in m (outputs x 1e3), 4 rules, no design defaults.

(45) then needs sigma of order 1e-11: four orders of magnitude and more from any default. The bounds, posed
in the plant's own time and output size, find it. The generic gamma, gamma1 and sigma are taken in the
outputs' own size and step 5's objective weighs the observer gains by it, so the design does not depend on
the unit the outputs are measured in: the same plant measured in m or in mm (its sensor fault with it) gets
the same design, scaled. (Before, with the generic values as absolute numbers, the mm plant needed a sample
time of 3.6e-4 s where the m plant runs at 1 s.) This plant's level bias is in mm on outputs in mm; at a
sample time of 1 s it is refused by a narrow margin and the refusal names the sample time that works, which
then certifies."""

from __future__ import annotations

import re

import casadi as ca
import pytest

from fte_casadi import PlantBuilder
from fte_casadi.design import augment, design
from fte_casadi.design.core._diagnose import sigma_max
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive


def slow_plant(n: int = 4, q: int = 2, sy: float = 1e3, bias_scaled: bool = False):
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
    b.outputs([sy * (x[0] + fs) if bias_scaled else sy * x[0] + fs] + [sy * xk for xk in x])
    b.region(**{f"x{k + 1}": (-1.0, 1.0) for k in range(n)})
    return b.build()


@pytest.fixture(scope="module")
def ts():
    return derive(slow_plant(), fidelity_samples=300)


def test_the_bounds_find_a_sigma_four_orders_below_the_defaults(ts):
    aug = augment(ts.local_models, ts.C, ts.Df)
    sup, status = sigma_max(aug, None, 0.5, "CLARABEL")
    assert sup is not None and 1e-13 < sup < 1e-9, (sup, status)


@pytest.mark.heavy
def test_the_refusal_names_the_sample_time_and_that_one_certifies(ts):
    """40 s on the 2-core machine: tests/test_sample_time.py checks the same route on the manipulator in 6 s, and
    test_generic_values_follow_the_outputs_size (below) the sigma in the outputs' own size: `pytest -m heavy`."""
    with pytest.raises(InfeasibleDesignError) as exc:
        design(ts, sample_time=1.0)
    msg = " ".join(str(exc.value).split())
    assert "refused for other reasons" in msg and "no certified design runs at the sample time 1" in msg
    ts_ok = float(re.search(r"sample time <= ([0-9.e+-]+)", msg).group(1))
    assert 0.05 < ts_ok < 1.0
    d = design(ts, sample_time=ts_ok)
    assert d.certified and d.checks["discrete"]["holds"]
    assert d.params.sigma < 1e-9 and "sigma" in d.params_chosen
    assert any("outputs' own size" in s for s in d.status)


@pytest.mark.slow
def test_the_design_does_not_depend_on_the_outputs_unit():
    """The plant with every output (and its sensor bias) in units 1024 times smaller. At its defaults both
    certify at a sample time of 1 s with the same largest sample time up to the rounding of the sigma the
    tool chooses (decimal, in each plant's units). At parameters in the same relation (sigma / 1024^2,
    gamma and gamma1 x 1024): the same K, decay rate and largest sample time, Pbar 1024^2 times larger and
    the observer gains 1024 times smaller (a power of two: the change of units is exact in floating point)."""
    import numpy as np

    plants = [derive(slow_plant(sy=sy, bias_scaled=True), fidelity_samples=300) for sy in (1.0, 1024.0)]
    a, b = (design(ts, sample_time=1.0) for ts in plants)
    assert a.certified and b.certified
    assert b.checks["ts_max"] == pytest.approx(a.checks["ts_max"], rel=0.02)
    a, b = (design(ts, sample_time=1.0, sigma=1.9e-5 / c**2, gamma=c, gamma1=0.5 * c)
            for ts, c in zip(plants, (1.0, 1024.0)))  # fmt: skip
    assert a.certified and b.certified
    assert b.observer.alpha == pytest.approx(a.observer.alpha, rel=1e-6)
    assert b.checks["ts_max"] == pytest.approx(a.checks["ts_max"], rel=1e-6)
    np.testing.assert_allclose(np.asarray(b.K[0]), np.asarray(a.K[0]), rtol=1e-6)
    np.testing.assert_allclose(np.asarray(b.Pbar), 1024.0**2 * np.asarray(a.Pbar), rtol=1e-5,
                               atol=1e-8 * 1024.0**2 * np.abs(a.Pbar).max())  # fmt: skip
    np.testing.assert_allclose(np.asarray(b.L1[0]), np.asarray(a.L1[0]) / 1024.0, rtol=1e-5,
                               atol=1e-8 * np.abs(a.L1[0]).max())  # fmt: skip


@pytest.mark.slow
def test_an_unstable_mode_barely_reachable_is_named(ts):
    """Coupled more strongly than it decays, the chain is open-loop unstable and its one input, at the chain's
    head, reaches the unstable modes only weakly: the reason (45) may leave no margin sigma at all."""
    from fte_casadi.design._limits import reachability

    assert reachability(augment(ts.local_models, ts.C, ts.Df)) == ""  # the 4-stage chain is stable
    long_chain = derive(slow_plant(16, 4), fidelity_samples=200)
    why = reachability(augment(long_chain.local_models, long_chain.C, long_chain.Df))
    assert "open loop is unstable" in why
    pbh = float(re.search(r"\|\| = ([0-9.e+-]+)", why).group(1))
    assert 0 < pbh < 0.05


def test_generic_values_follow_the_outputs_size(ts):
    """The generic gamma, gamma1, sigma in the outputs' own size (sy = 1024 here), gamma and gamma1 also in the
    unknown input's (sd); gamma1, when not given, is in that size even beside a given gamma, lowered below it
    where needed; a generic gamma rises above a given gamma1; given values are kept."""
    from fte_casadi.design._options import _params, generic_sizes

    def params(**given):
        full = {k: given.get(k) for k in ("gamma", "gamma1", "sigma", "delta", "epsilon")}
        return _params(ts, full, [])

    sy, sd = generic_sizes(ts)
    assert sy == 1024.0 and 0.01 < sd < 1.0
    p = params()
    assert (p["gamma"], p["gamma1"], p["sigma"]) == (sy * sd, 0.5 * sy * sd, 1024.0**-2)
    assert params(gamma=2000.0)["gamma1"] == 0.5 * sy * sd  # in d's size, below the given gamma
    assert params(gamma=10.0)["gamma1"] == 5.0  # lowered below a given gamma
    assert params(gamma1=1.0)["gamma"] == sy * sd
    assert params(gamma1=2 * sy)["gamma"] == 4 * sy  # the generic gamma raised above a given gamma1
    assert params(sigma=3e-11)["sigma"] == 3e-11 and p["delta"] == 1e-4  # delta, epsilon are not scaled
