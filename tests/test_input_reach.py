"""Where the input limits leave the loop's certificate intact: the largest level set of step 3's Lyapunov function
on which no input saturates (`checks["loop"]["unsaturated"]`, printed by `fte design`). A certified levitation
whose gain of 2.6e5 V/mm saturated its coil for 26 nm of gap diverged in its first 0.1 s, fault-free, while
`fte design` printed only CERTIFIED."""

from __future__ import annotations

import pathlib

import numpy as np
import pytest

from fte_casadi.design._recertify import unsaturated
from fte_casadi.design._summary import SATURATES_EARLY, _unsaturated_line, design_summary


def _sqrtm(X):
    w, V = np.linalg.eigh(X)
    return V @ np.diag(np.sqrt(w)) @ V.T


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_it_is_the_largest_level_set_on_which_every_input_stays_within_its_limits(seed):
    rng = np.random.default_rng(seed)
    n, m = 4, 2
    M = rng.normal(size=(n, n))
    X = M @ M.T + 0.1 * np.eye(n)
    K = [rng.normal(size=(m, n)) * 10 ** rng.uniform(-1, 2, size=(m, 1)) for _ in range(2)]
    x_ref = rng.normal(size=n)
    u_ref = rng.normal(size=m)
    u0 = u_ref + K[0] @ x_ref
    lim = np.column_stack([u0 - rng.uniform(0.5, 3, m), u0 + rng.uniform(0.5, 3, m)])
    lo, hi = x_ref - 5.0, x_ref + 5.0
    room = unsaturated(X, K, u0, lim, {"lo": list(lo), "hi": list(hi)})
    head = np.asarray(room["headroom"])
    np.testing.assert_allclose(head, np.minimum(lim[:, 1] - u0, u0 - lim[:, 0]), rtol=1e-12)
    # c from the reach: extent_k = sqrt(c X_kk)
    c = room["extent"][0] ** 2 / X[0, 0]
    S = _sqrtm(X)
    # every point of the level set {(x - x_ref)' X^-1 (x - x_ref) <= c} keeps every input within its limits ...
    z = rng.normal(size=(n, 20000))
    dx = np.sqrt(c) * S @ (z / np.linalg.norm(z, axis=0))
    worst = max(np.max(np.abs(k @ dx) / head[:, None]) for k in K)
    assert worst <= 1 + 1e-9
    # ... and at its boundary's worst point an input reaches its limit: no larger level set does
    reach = max(float(np.sqrt(c) * np.linalg.norm(S @ k[i])) / head[i] for k in K for i in range(m))
    assert reach == pytest.approx(1.0, rel=1e-9)
    # its reach along each state is attained: the boundary point x_ref + sqrt(c) X e_k / sqrt(X_kk)
    for k in range(n):
        pt = np.sqrt(c) * X[:, k] / np.sqrt(X[k, k])
        assert pt[k] == pytest.approx(room["extent"][k], rel=1e-12)
        assert pt @ np.linalg.solve(X, pt) == pytest.approx(c, rel=1e-9)
    assert room["fraction"] == pytest.approx(min(room["extent"]) / 5.0, rel=1e-12)


def test_no_limits_no_record_and_an_input_at_rest_beyond_a_limit_leaves_nothing():
    X, K = np.eye(2), [np.array([[1.0, 2.0]])]
    assert unsaturated(X, K, [0.0], None, {"lo": [-1, -1], "hi": [1, 1]}) is None
    room = unsaturated(X, K, [2.0], [[-1.0, 1.0]], {"lo": [-1, -1], "hi": [1, 1]})
    assert room["extent"] == [0.0, 0.0] and room["fraction"] == 0.0
    room = unsaturated(X, K, [0.0], [[-1.0, 1.0]], {"lo": [None, -1], "hi": [None, 1]})
    assert room["region_half_width"][0] is None and room["fraction"] == pytest.approx(room["extent"][1])


def test_a_reach_far_below_the_region_is_a_warning():
    small = {"headroom": [10.0], "extent": [2.6e-5, 1.9e-3], "region_half_width": [3.0, 250.0],
             "fraction": 2.6e-5 / 3.0}  # fmt: skip
    assert "warning" in _unsaturated_line(small, ["e", "v"])
    wide = dict(small, extent=[1.0, 100.0], fraction=1.0 / 3.0)
    assert "warning" not in _unsaturated_line(wide, ["e", "v"])
    assert SATURATES_EARLY < 1.0 / 3.0


def test_the_design_records_and_prints_it(real_designs):
    limited = [k for k, d in real_designs.items() if d.input_limits is not None]
    assert limited  # the three-tank's pumps
    for name in limited:
        d = real_designs[name]
        room = d.checks["loop"]["unsaturated"]
        region = {k: [np.nan if v is None else v for v in vs] for k, vs in d.checks["region"].items()}
        u0 = (
            d.u_ref if d.x_ref is None else d.u_ref + np.asarray(d.K[0]) @ np.asarray(d.x_ref)
        )  # one common K
        again = unsaturated(d.X, d.K, u0, d.input_limits, region)
        np.testing.assert_allclose(room["extent"], again["extent"], rtol=1e-12)
        assert "input limits: u stays within them" in design_summary(d)
    assert "unsaturated" not in real_designs["manipulator"].checks["loop"]  # no input limits
    assert "input limits: u stays" not in design_summary(real_designs["manipulator"])


def test_a_saturated_window_is_explained_by_a_reach_that_small(real_designs):
    import dataclasses

    from fte_casadi.design import explain_metrics

    d = real_designs["three-tank"]
    room = dict(d.checks["loop"]["unsaturated"])
    faults = list(d.names["faults"])

    def explained(fraction, saturation):
        checks = dict(d.checks, loop=dict(d.checks["loop"], unsaturated=dict(room, fraction=fraction)))
        w = {"fault": faults[0], "start": 300.0, "stop": 400.0, "ftc_true_ratio": 1.0, "fault_rel_rms_error": 0.1,
             "input_saturation": [saturation, 0.0]}  # fmt: skip
        text = " ".join(explain_metrics(dataclasses.replace(d, checks=checks), {"windows": [w]}, windows=[0]))
        return "keeps its inputs within their limits only" in text

    assert explained(1e-4, 0.5)
    assert not explained(1e-4, 0.0)  # nothing saturated: nothing to explain
    assert not explained(0.5, 0.5)  # a reach that large is not the cause


def test_the_largest_reach_bounds_the_design_s_and_scales_with_the_limits(real_designs):
    """``reach_max``: the design's own point is feasible for it, so it is at least the design's reach; and its
    constraints are homogeneous but for the inputs' headroom, so halving every headroom halves it."""
    from fte_casadi.design import augment
    from fte_casadi.design.core._diagnose import reach_max

    d = real_designs["three-tank"]
    room = d.checks["loop"]["unsaturated"]
    aug = augment(d.local_models, d.C, d.Df)
    params = {
        "sigma": d.params.sigma,
        "gamma": d.params.gamma,
        "gamma1": d.params.gamma1,
        "beta": d.params.beta,
    }
    assert params["beta"]  # the decay LMI is posed too: the design's point satisfies it at the recorded rate
    best, status = reach_max(aug, params, room["headroom"], room["region_half_width"], "CLARABEL")
    assert status == "optimal" and best >= room["fraction"] * (1 - 1e-6)
    half, _ = reach_max(
        aug, params, [0.5 * h for h in room["headroom"]], room["region_half_width"], "CLARABEL"
    )
    assert half == pytest.approx(0.5 * best, rel=1e-4)


def test_the_warning_says_whether_the_gain_or_the_region_binds():
    room = {
        "headroom": [10.0],
        "extent": [2.6e-5, 1.9e-3],
        "region_half_width": [3.0, 250.0],
        "fraction": 8.7e-6,
    }
    assert "the region, not the gain, binds" in _unsaturated_line(dict(room, fraction_max=0.0019), ["e", "v"])
    assert "a gain with a larger reach exists" in _unsaturated_line(
        dict(room, fraction_max=0.048), ["e", "v"]
    )
    rate = dict(room, fraction_max=0.0099, fraction_max_without_decay=0.048, beta=5.87)
    assert "the loop's decay rate leaves the input no room" in _unsaturated_line(rate, ["e", "v"])
    assert "the region, not the gain, binds" in _unsaturated_line(
        dict(rate, fraction_max_without_decay=0.002), ["e"]
    )


@pytest.mark.slow
def test_a_default_loop_rate_that_leaves_the_inputs_no_room_is_lowered():
    """The levitation in the region it runs in: at the default loop rate (as fast as it diverges, 42.7/s once
    (45) lowered it) its gain keeps the coil within its limits on 0.34 % of the region, so the loop is designed
    again with the smallest gain, reaching 7.6 %; a rate the user gives is kept, reach or not."""
    import sys

    from fte_casadi.design import design
    from fte_casadi.ts import derive

    sys.path.insert(0, str(pathlib.Path(__file__).parent))
    from plant_levitation import maglev_near, scenario

    ts = derive(maglev_near(), fidelity_samples=200)
    opts = dict(sample_time=scenario().dt, settle_window=0.0)
    d = design(ts, **opts)
    room = d.checks["loop"]["unsaturated"]
    assert d.certified and room["fraction"] >= SATURATES_EARLY
    assert any("keeps its inputs within their limits only on a set reaching" in n for n in d.status)
    asked = design(ts, beta=40.0, **opts)  # the user's rate: kept, and the reach is what it is
    assert asked.checks["loop"]["unsaturated"]["fraction"] < SATURATES_EARLY
