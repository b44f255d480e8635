"""Robustness sweeps (issue #11): a grid of factors, one metrics document per point, a figure."""

from __future__ import annotations

import json

import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.errors import ParameterError
from fte_casadi.sim import simulate
from fte_casadi.sim._sweep import parse_vary, sweep, to_csv


def test_parse_vary_validates():
    assert parse_vary(["fault_scale=0.5,1,2", "noise_scale=0,3"]) == {
        "fault_scale": [0.5, 1, 2],
        "noise_scale": [0, 3],
    }
    for bad, match in ((["speed=1"], "unknown factor"), (["fault_scale"], "NAME=V1"), (["d_scale=a"], "numbers"),
                       (["d_scale=-1"], "non-negative"), ([], "at least one"), (["d_scale=1", "d_scale=2"], "twice")):  # fmt: skip
        with pytest.raises(ParameterError, match=match):
            parse_vary(bad)


def test_sweep_over_two_factors(plants, real_designs, tmp_path):

    from fte_casadi.plants import SCENARIOS

    d, p = real_designs["manipulator"], plants["manipulator"]
    sc = SCENARIOS["manipulator"]().until(6.0)  # the actuator window only
    pts = sweep(
        d, p, sc, {"fault_scale": [0.5, 2.0], "noise_scale": [0.0, 1.0]}, paths=8, seed=2, progress=False
    )
    assert [pt["point"] for pt in pts] == [
        {"fault_scale": a, "noise_scale": b} for a in (0.5, 2.0) for b in (0.0, 1.0)
    ]
    # each point is the metrics document of a run with those factors
    one = simulate(
        d, p, sc, paths=8, seed=2, progress=False, scales={"fault_scale": 2.0, "noise_scale": 0.0}
    ).metrics
    got = dict(pts[2]["metrics"])
    got.pop("wall_s"), one.pop("wall_s")
    assert got == one
    # a larger fault moves the estimate further, and noise changes the error
    e = {tuple(pt["point"].values()): pt["metrics"]["fault_rel_rms_error"][0] for pt in pts}
    assert e[(0.5, 0.0)] != e[(0.5, 1.0)]
    rows = to_csv(pts).strip().splitlines()
    assert len(rows) == 5 and rows[0].startswith("fault_scale,noise_scale,fault_rel_rms_error_0")


@pytest.mark.slow
def test_cli_sweep_prints_points_and_writes_figure(tmp_path):
    r = CliRunner().invoke(main, ["sweep", "manipulator", "--vary", "fault_scale=0.5,1,2", "--paths", "16", "--seed", "1",
                                  "--json", "--quiet", "--out", str(tmp_path)])  # fmt: skip
    assert r.exit_code == 0, r.output
    pts = json.loads(r.stdout)
    assert [p["point"] for p in pts] == [{"fault_scale": 0.5}, {"fault_scale": 1.0}, {"fault_scale": 2.0}]
    assert all({"windows", "input_saturation", "ftc_true_ratio"} <= set(p["metrics"]) for p in pts)
    assert (tmp_path / "sweep.png").stat().st_size > 10_000
    assert json.loads((tmp_path / "sweep.json").read_text()) == pts
    assert (tmp_path / "sweep.csv").read_text().count("\n") == 4


def test_cli_sweep_bad_factor_is_one_paragraph():
    r = CliRunner().invoke(main, ["sweep", "manipulator", "--vary", "gain=1,2"])
    assert r.exit_code == 2 and "unknown factor 'gain'" in r.output and "Traceback" not in r.output


def test_a_fault_scale_beyond_a_full_loss_is_refused_before_any_point_runs(plants, real_designs):
    from fte_casadi.plants import SCENARIOS

    with pytest.raises(
        ParameterError, match=r"loss of effectiveness of 'fa' .* a loss of 120 %.*fault_scale <= 2.5"
    ):
        sweep(real_designs["manipulator"], plants["manipulator"], SCENARIOS["manipulator"](),
              {"fault_scale": [1.0, 3.0]}, paths=4, seed=0, progress=False)  # fmt: skip


@pytest.mark.slow
def test_cli_sweep_warns_by_point_where_tolerant_control_is_worse_than_none(monkeypatch):
    """The per-window verdict of fte simulate, for every point of a sweep, on stderr (also with --json)."""
    import fte_casadi.sim._sweep as sweep_module

    def fake(d, plant, scenario, grid, **kw):
        w = {"fault": "fa", "start": 2.0, "stop": 4.0, "fault_rel_rms_error": 0.1, "input_saturation": [0.0]}
        return [{"point": {"fault_scale": s}, "metrics": {"windows": [dict(w, ftc_true_ratio=r)]}}
                for s, r in ((1.0, 0.3), (3.0, 1.75))]  # fmt: skip

    monkeypatch.setattr(sweep_module, "sweep", fake)
    r = CliRunner().invoke(main, ["sweep", "manipulator", "--vary", "fault_scale=1,3", "--json", "--quiet"])
    assert r.exit_code == 0, r.output
    assert len(json.loads(r.stdout)) == 2
    assert r.stderr.count("worse than none") == 1
    assert "at fault_scale = 3: warning: in the window of fa [2, 4)" in r.stderr and "1.75 > 1" in r.stderr
