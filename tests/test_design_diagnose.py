"""Tests of fte_casadi.design.core._diagnose and the bounds an infeasible design names (issue #9)."""

from __future__ import annotations

import functools
import re
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner
from plant_tight import tight

from fte_casadi._rounding import nice_ceil, nice_floor
from fte_casadi.cli import main
from fte_casadi.design import augment, design, explore
from fte_casadi.design.core._diagnose import gamma_min, sigma_max
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive

HERE = Path(__file__).resolve().parent


@pytest.fixture(scope="module")
def ts():
    return derive(tight(), fidelity_samples=300)


def test_nice_rounding():
    assert nice_ceil(0.4431) == pytest.approx(0.45) and nice_floor(0.0821) == pytest.approx(0.082)
    assert nice_ceil(3.0) == pytest.approx(3.0) and nice_floor(120.7) == pytest.approx(120.0)


def test_bounds_of_lmi_45(ts):
    aug = augment(ts.local_models, ts.C, ts.Df)
    sup, status = sigma_max(aug, None, 0.1, "CLARABEL")
    assert status == "optimal" and 0.05 < sup < 0.12  # measured 0.0855
    at2, _ = sigma_max(aug, 2.0, 0.1, "CLARABEL")
    assert at2 <= sup  # a finite gamma allows less than every gamma
    assert gamma_min(aug, 0.5, 0.1, "CLARABEL")[0] is None  # sigma = 0.5 is beyond every gamma
    g, _ = gamma_min(aug, 0.5 * sup, 0.1, "CLARABEL")
    assert g is not None and g >= 0.1


@pytest.mark.slow
def test_infeasible_defaults_name_a_bound_that_gives_a_certified_design(ts):
    with pytest.raises(InfeasibleDesignError) as exc:
        design(ts)
    msg = str(exc.value)
    assert "LMI (45) is infeasible" in msg and "no gamma makes (45) feasible at sigma = 0.5" in msg
    sig = float(re.search(r"lower sigma to <= ([0-9.e+-]+)", msg, re.I).group(1))
    assert sig < 0.09
    d = design(ts, sigma=sig)
    assert d.certified and all(v < 0 for v in d.checks["lmi_max_eig"].values())


@pytest.mark.slow
def test_cli_prints_the_bounds_as_one_paragraph():
    r = CliRunner().invoke(main, ["design", f"{HERE / 'plant_tight.py'}:tight"])
    assert r.exit_code == 1
    assert "Traceback" not in r.output and "lower sigma to <=" in r.output.lower()


@pytest.mark.slow
def test_explore_frontier_and_figure(ts, tmp_path, monkeypatch):
    points, info = explore(ts, count=4)
    assert len(points) == 4 and info["sigma_sup"] > 0
    sig = [p.sigma for p in points]
    assert sig == sorted(sig) and sig[-1] < info["sigma_sup"]
    gm = [p.gamma_min for p in points if p.gamma_min is not None]
    assert gm == sorted(gm)  # the smallest feasible gamma grows with sigma
    assert any(p.certified for p in points)
    for p in points:
        if p.certified:
            assert p.gamma_tried >= p.gamma_min and design(ts, sigma=p.sigma, gamma=p.gamma_tried).certified
            break
    # the command's frontier over 4 sigmas, not its 12: what is checked here is its output and figure, the frontier above
    monkeypatch.setattr(sys.modules["fte_casadi.design"], "explore", functools.partial(explore, count=4))
    r = CliRunner().invoke(
        main, ["design", f"{HERE / 'plant_tight.py'}:tight", "--explore", "--out", str(tmp_path)]
    )
    assert r.exit_code == 0, r.output
    assert (tmp_path / "frontier-tight.png").stat().st_size > 10_000
    assert "gamma_min (45)" in r.output
