"""fte tune (issue #18 items 2 and 4): the front, the chosen design, reproducibility, the files, the
limits named when no design helps, and the kappa / boundary-layer knobs it searches."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.design import Design, design
from fte_casadi.design._limits import channel_zeros, explain_metrics
from fte_casadi.design.core._certify import failures
from fte_casadi.errors import ParameterError
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.ts import derive

pytest.importorskip("optuna")

from fte_casadi.tune import (  # noqa: E402
    Record,  # noqa: E402
    TuneOptions,
    choose,
    pareto_front,
    tune,
)

SPEC = f"{Path(__file__).parent / 'plant_tune.py'}:plant"
#: every test here searches and simulates many candidates: the module took over 20 minutes on the shared
#: 2-core machine (python3 -m pytest --durations=0 tests/test_tune.py), so all of it is left out of the fast subset
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def small():
    plant, scenario = load_plant(SPEC), load_scenario(SPEC)
    ts = derive(plant)
    base = design(ts, sample_time=scenario.dt, initial_state=scenario.x0, plant_spec=SPEC)
    return plant, scenario, ts, base


@pytest.fixture(scope="module")
def result(small):
    plant, scenario, _, base = small
    return tune(base, plant, scenario, trials=7, seed=3, paths=2)


def _dominates(a, b) -> bool:
    a, b = np.asarray(a), np.asarray(b)
    return bool(np.all(a <= b) and np.any(a < b))


def test_front_is_non_dominated_and_certified(result):
    done = [r for r in result.records if r.state == "ok"]
    assert result.records[0].number == 0 and result.records[0].state == "ok"  # the base design is trial 0
    assert len(result.records) == 7 and len(done) >= 3
    front = [result.record(k) for k in result.front]
    for f in front:
        assert not any(_dominates(r.values, f.values) for r in done)
        d = Design.from_dict(json.loads(f.design))
        assert d.certified and failures(d.checks) == []
        assert max(d.checks["lmi_max_eig"].values()) < 0
    for r in done:  # every completed trial off the front is dominated by (or equal to) a front member
        if r.number not in result.front:
            assert any(_dominates(f.values, r.values) or f.values == r.values for f in front)
    assert result.chosen in result.front
    for r in result.records:  # a failed trial carries its reason
        assert (r.state == "ok") == (r.reason is None)


def test_objectives_are_the_metrics(result):
    base = result.records[0]
    names = result.objectives
    v = dict(zip(names, base.values))
    assert v["fault_error[fa]"] == base.metrics["fault_rel_rms_error"][0]
    assert v["false_alarm[fs]"] == base.metrics["false_alarm_peak"][1]
    assert v["ftc[fs@3.5]"] == base.metrics["windows"][1]["ftc_true_ratio"]
    assert v["input_peak"] == 1.0  # relative to the base design's own peak
    assert "input_saturation" not in names  # the plant has no input limits


def test_reproducible_for_a_seed(small, result):
    """The same seed gives the same trials, front and choice: run again through the options record
    (``TuneOptions``, not keywords) on a Dask cluster (one worker, in this process), against the module's run by
    keywords in process. Another seed gives other trials."""
    distributed = pytest.importorskip("distributed")
    plant, scenario, _, base = small
    with distributed.LocalCluster(
        n_workers=1, threads_per_worker=2, processes=False, dashboard_address=None
    ) as c:
        with distributed.Client(c) as client:
            again = tune(
                base, plant, scenario, options=TuneOptions(trials=7, seed=3, paths=2, scheduler=client)
            )
    assert [r.values for r in again.records] == [r.values for r in result.records]
    assert [r.knobs for r in again.records] == [r.knobs for r in result.records]
    assert again.front == result.front and again.chosen == result.chosen
    other = tune(base, plant, scenario, trials=3, seed=4, paths=2)
    assert [r.knobs for r in other.records[1:]] != [r.knobs for r in result.records[1:3]]


def _rec(k, values, ftc=0.5, fa=0.5):
    m = {"windows": [{"ftc_true_ratio": ftc}], "false_alarm_peak": [fa]}
    return Record(k, {}, "ok", {}, m, None, tuple(values))


def test_choose_rules():
    names = ("fault_error[f]", "false_alarm[f]", "ftc[f@1]", "input_peak")
    recs = [_rec(0, (0.2, 0.5, 0.5, 1.0)), _rec(1, (0.1, 0.4, 0.4, 1.2)), _rec(2, (0.05, 0.6, 0.3, 1.0)),
            _rec(3, (0.01, 0.3, 0.2, 3.0))]  # fmt: skip
    front = [0, 1, 2, 3]
    # balanced: trial 1 is better than the base on every fault objective; 3 is better still but its
    # input peak is 3 x the base's (beyond the 1.5 allowance)
    assert choose(recs, front, names, "balanced")[0] == 1
    assert choose(recs, front, names, "fault-error")[0] == 3
    assert choose(recs, front, names, "false-alarm")[0] == 3
    # a design whose FTC ratio is >= 1 in a window is taken only when nothing else is left
    recs[3] = _rec(3, (0.01, 0.3, 0.2, 1.0), ftc=1.2)
    assert choose(recs, front, names, "fault-error")[0] == 2
    with pytest.raises(ParameterError, match="unknown objective"):
        choose(recs, front, names, "speed")
    # of the designs better than the base on every fault objective, the one better by the most on the
    # whole (geometric mean of the ratios: 2's), not the one whose worst ratio is smallest (1's 0.8)
    recs = [_rec(0, (0.2, 0.5, 0.5, 1.0)), _rec(1, (0.16, 0.4, 0.4, 1.0)), _rec(2, (0.02, 0.45, 0.45, 1.0)),
            _rec(3, (0.01, 0.6, 0.1, 1.0))]  # fmt: skip
    assert choose(recs, front, names, "balanced")[0] == 2
    # none better on every one: the base (score 1), or without it the smallest worst ratio (3's 1.2
    # against 1.5)
    recs[1], recs[2] = _rec(1, (0.3, 0.4, 0.4, 1.0)), _rec(2, (0.02, 0.75, 0.1, 1.0))
    assert choose(recs, front, names, "balanced")[0] == 0
    assert choose(recs, [1, 2, 3], names, "balanced")[0] == 3
    assert pareto_front([(1, 2), (2, 1), (2, 2), (1, 2)]) == [0, 1]


def test_ftc_rule_judges_ties_as_the_verdicts_do():
    """A ratio above 1 whose interval holds 1 is a tie (not worse than none), as ``fte simulate`` warns; the
    ``ftc`` rule compares the windows' judged ratios worst first, so a design whose tolerant control ties in
    every window (here 0.99999 and 0.99998: it does nothing) is not chosen over the base, which ties in the
    sensor window and helps in the actuator one (0.709). Judged by the bare worst ratio, it was."""
    from fte_casadi.tune._search import _admissible

    names = ("fault_error[fa]", "ftc[fa@0.5]", "ftc[fs@1.75]")

    def rec(k, fe, ratios):
        wins = [{"ftc_true_ratio": r, "ftc_true_ratio_interval": iv} for r, iv in ratios]
        m = {"windows": wins, "false_alarm_peak": [0.1]}
        return Record(k, {}, "ok", {}, m, None, (fe, *(r for r, _ in ratios)))

    base = rec(0, 0.24, [(0.709, [0.70, 0.89]), (1.00002, [0.9999, 1.0001])])
    idle = rec(1, 0.43, [(0.99999, [0.9999, 1.00001]), (0.99998, [0.9999, 1.00001])])
    assert _admissible(base.metrics) == (True, True, True)  # the tie above 1 (1.00002 to 0.001) is not worse
    assert choose([base, idle], [0, 1], names, "ftc")[0] == 0
    # measurably worse (its interval above 1): then it is, and a design that helps everywhere is taken
    worse = rec(0, 0.24, [(0.709, [0.70, 0.89]), (1.02, [1.01, 1.03])])
    assert _admissible(worse.metrics) == (False, False, True)
    assert choose([worse, idle], [0, 1], names, "ftc")[0] == 1
    better = rec(2, 0.3, [(0.6, [0.5, 0.7]), (0.99, [0.98, 0.995])])
    assert choose([base, idle, better], [0, 1, 2], names, "ftc")[0] == 2
    # the levitation's tune (maglev_near, 30 trials): the default worse than none by 1.2e-7 in the sensor window
    # (its interval above 1: the runs share their paths), trial 13's tolerant control doing next to nothing; to
    # the resolution of 0.001 both tie there, and the default's 0.709 decides
    lev = rec(0, 0.24, [(0.7092, [0.698, 0.7235]), (1.0000001164, [1.0000000701, 1.000000159])])
    nothing = rec(13, 0.43, [(0.99996709, [0.99996015, 0.9999747]), (0.99995242, [0.9999524, 0.99999984])])
    assert _admissible(lev.metrics) == (True, True, True)
    assert choose([lev, nothing], [0, 1], names, "ftc")[0] == 0


def test_an_output_worse_than_none_keeps_a_design_out():
    """#38: tolerant control no worse than none on any output. The three-tank's tune (60 trials, seed 1, 20 paths):
    the base and trial 11 (the base's epsilon doubled, a hair better on every objective) leave h1 worse, 1.0079
    (interval 1.0012-1.0163) and 1.0077 (0.9999-1.0158: a tie by the interval); trial 9 (kappa doubled) measures
    h1 0.9918 for a fault error of 0.274 against 0.270. The window as a whole, 0.199, hid h1 from the tiers."""
    from fte_casadi.tune._search import _admissible

    names = ("fault_error[fa]", "false_alarm[fa]", "ftc[fa@200]")

    def rec(k, values, h1, h1_iv):
        w = {
            "ftc_true_ratio": values[2],
            "ftc_true_ratio_interval": [values[2] - 0.01, values[2] + 0.01],
            "ftc_true_ratio_per_output": [h1, 0.19],
            "ftc_true_ratio_per_output_interval": [h1_iv, [0.18, 0.2]],
        }
        return Record(k, {}, "ok", {}, {"windows": [w], "false_alarm_peak": [values[1]]}, None, tuple(values))

    base = rec(0, (0.270, 0.712, 0.199), 1.0079, [1.0012, 1.0163])
    tie = rec(11, (0.269, 0.708, 0.199), 1.0077, [0.9999, 1.0158])
    kappa2 = rec(9, (0.274, 0.760, 0.182), 0.9918, [0.9837, 1.001])
    assert _admissible(base.metrics) == (False, False, False)
    assert _admissible(tie.metrics) == (True, False, False)
    assert _admissible(kappa2.metrics) == (True, True, False)
    chosen, tier = choose([base, tie, kappa2], [0, 1, 2], names, "balanced")
    assert chosen == 9 and tier.startswith("tolerant control measured no worse than none")
    # without a member measuring every ratio <= 1, the tie by the interval; without that, all of them
    assert choose([base, tie], [0, 1], names, "balanced")[0] == 11
    assert choose([base], [0], names, "balanced")[1].startswith("none of the front")
    # the window's ratio alone (no per-output figures) is judged as before
    alone = Record(
        0, {}, "ok", {}, {"windows": [{"ftc_true_ratio": 0.199}], "false_alarm_peak": [0.3]}, None, ()
    )
    assert _admissible(alone.metrics) == (True, True, True)


def test_the_comparison_shows_tolerant_control_after_each_window():
    """The "default vs chosen" table has the span after a window (``after_window``) beside the window, per output,
    where both documents measured it, and counts it among the fault metrics of ``dominates``."""
    from fte_casadi.tune import comparison, dominates

    def doc(after_h1):
        a = {"ftc_true_ratio": 0.9, "ftc_true_ratio_per_output": [after_h1, 0.8]}
        w = {"fault": "fa", "start": 200.0, "stop": 400.0, "fault_rel_rms_error": 0.27, "ftc_true_ratio": 0.18,
             "ftc_true_ratio_per_output": [0.99, 0.17], "after_window": a}  # fmt: skip
        return {"fault_rel_rms_error": [0.27], "false_alarm_peak": [0.7], "windows": [w], "ftc_true_ratio": 0.18,
                "input_peak": [43.0], "input_saturation": [0.0], "state_rms_error": [0.01]}  # fmt: skip

    rows = comparison(doc(1.09), doc(0.99), ["fa"], ["Q"], ["h1", "h2"])
    after = {name: (b, c) for name, b, c in rows if name.startswith("FTC ratio after window fa [200, 400)")}
    assert after == {"FTC ratio after window fa [200, 400)": (0.9, 0.9),
                     "FTC ratio after window fa [200, 400), h1": (1.09, 0.99),
                     "FTC ratio after window fa [200, 400), h2": (0.8, 0.8)}  # fmt: skip
    assert dominates(rows) and not dominates(comparison(doc(0.99), doc(1.09), ["fa"], ["Q"], ["h1", "h2"]))
    old = doc(1.0)
    old["windows"][0].pop("after_window")  # a document from before it was measured: no row
    assert not any("after window" in r[0] for r in comparison(old, doc(0.99), ["fa"], ["Q"], ["h1", "h2"]))


def test_cli_json_files_and_tuned_design_simulates(tmp_path):
    out = tmp_path / "t"
    r = CliRunner().invoke(main, ["tune", SPEC, "--trials", "4", "--seed", "2", "--paths", "2", "--out", str(out),
                                  "--json", "--quiet"])  # fmt: skip
    assert r.exit_code == 0, r.output
    front = json.loads(r.stdout)
    assert isinstance(front, list) and front
    assert front[0]["chosen"] and sum(p["chosen"] for p in front) == 1
    for p in front:
        assert set(p) >= {"params", "metrics", "design"}
        assert {"gamma", "gamma1", "sigma", "alpha", "kappa", "epsilon"} <= set(p["params"])
        for key in ("fault_rel_rms_error", "false_alarm_peak", "ftc_true_ratio", "windows",
                    "input_saturation", "input_peak"):  # fmt: skip
            assert key in p["metrics"]
        assert Design.load(p["design"]).certified
    assert (out / "pareto.png").stat().st_size > 1000
    record = json.loads((out / "tune.json").read_text())
    assert len(record["trials"]) == 4 and record["chosen"] == front[0]["trial"]
    assert "default (trial 0) vs chosen" in r.stderr
    sim = CliRunner().invoke(main, ["simulate", str(out / "tuned.json"), "--plant", SPEC, "--paths", "2", "--json",
                                    "--quiet"])  # fmt: skip
    assert sim.exit_code == 0, sim.output
    m = json.loads(sim.stdout)
    chosen = front[0]["metrics"]  # the same seed? fte simulate's default seed is 0, tune's was 2: shapes only
    assert len(m["windows"]) == len(chosen["windows"]) == 2
    # a second run into the same directory replaces fte's own files
    r2 = CliRunner().invoke(main, ["tune", SPEC, "--trials", "2", "--seed", "2", "--paths", "2", "--out", str(out),
                                   "--quiet"])  # fmt: skip
    assert r2.exit_code == 0, r2.output
    assert len(json.loads((out / "tune.json").read_text())["trials"]) == 2


@pytest.mark.parametrize("name", ["tuned.json", "tune.json", "pareto.png", "designs/trial-0001.json"])
def test_refuses_to_overwrite_a_foreign_file(tmp_path, name):
    out = tmp_path / "t"
    f = out / name
    f.parent.mkdir(parents=True)
    f.write_text("my notes")
    r = CliRunner().invoke(main, ["tune", SPEC, "--trials", "3", "--out", str(out), "--quiet"])
    assert r.exit_code == 2
    assert "left untouched" in r.stderr and "Traceback" not in r.output
    assert f.read_text() == "my notes"
    assert not (out / "tuned.json").exists() or name == "tuned.json"


@pytest.mark.parametrize(
    "args, words",
    [(["--trials", "0"], "--trials must be at least 2"), (["--objective", "fastest"], "unknown --objective"),
     (["--seed", "-1"], "--seed must be"), (["--paths", "0"], "--paths must be")],
)  # fmt: skip
def test_bad_input_is_named(tmp_path, args, words):
    r = CliRunner().invoke(main, ["tune", SPEC, "--out", str(tmp_path / "t"), "--quiet", *args])
    assert r.exit_code == 2
    assert words in r.stderr and "Traceback" not in r.output
    assert not (tmp_path / "t").exists()


def test_channel_zeros():
    A = np.array([[0.0, 1.0], [-2.0, -3.0]])
    B = np.array([[0.0], [1.0]])
    # (s - 1) / ((s + 1)(s + 2)): a right-half-plane zero at 1
    z = channel_zeros(A, B, np.array([[-1.0, 1.0]]), np.zeros((1, 1)))
    assert np.allclose(z, [1.0])
    # a second output without that zero: the tall channel has none
    z2 = channel_zeros(A, B, np.array([[-1.0, 1.0], [1.0, 0.0]]), np.zeros((2, 1)))
    assert len(z2) == 0
    # fewer outputs than columns: rank lost for every s
    assert channel_zeros(A, np.eye(2), np.array([[1.0, 0.0]]), np.zeros((1, 2))) is None


def test_explain_names_the_limit_with_numbers(small):
    _, _, _, base = small
    m = {"windows": [{"fault": "fa", "start": 1.5, "stop": 1.6, "ftc_true_ratio": 1.7}],
         "false_alarm_peak": [None, 1.3]}  # fmt: skip
    lines = explain_metrics(base, m)
    assert len(lines) == 2
    tau = -1.0 / max(float(np.max(np.linalg.eigvals(R).real)) for R in base.R)
    # a 0.1-long window is shorter than the observer's settling: that is named, with its numbers
    assert "FTC ratio 1.7" in lines[0] and "slowest observer mode" in lines[0]
    assert f"{tau:.3g}" in lines[0]
    assert lines[1].startswith("false alarms of fs (ratio 1.3)")
    assert explain_metrics(base, {"windows": [dict(m["windows"][0], ftc_true_ratio=0.5)]}) == []


def test_kappa_bounds_the_conditioning(small):
    _, scenario, ts, base = small
    d = design(ts, sample_time=scenario.dt, kappa=1e2)
    assert d.params.kappa == 1e2 and base.params.kappa is None
    assert d.checks["cond_Pbar"] <= 1e2 * 1.01 < base.checks["cond_Pbar"]
    with pytest.raises(ParameterError, match="kappa"):
        design(ts, kappa=0.5)


def test_boundary_layer_of_the_design_is_the_step_s(small):
    import dataclasses

    from fte_casadi.step import step_function

    _, _, _, base = small
    phi = 1e-3
    d = dataclasses.replace(base, params=base.params.to_dict() | {"boundary_layer": phi})
    rng = np.random.default_rng(0)
    z, y = rng.normal(size=base.nbar) * 1e-4, rng.normal(size=base.C.shape[0]) * 1e-4
    own = [np.array(v) for v in step_function(d, 1e-3)(z, y)]
    asked = [np.array(v) for v in step_function(base, 1e-3, boundary_layer=phi)(z, y)]
    sgn = [np.array(v) for v in step_function(base, 1e-3)(z, y)]
    assert all(np.array_equal(a, b) for a, b in zip(own, asked))
    assert not all(np.array_equal(a, b) for a, b in zip(own, sgn))
    assert Design.from_dict(json.loads(d.to_json())).params.boundary_layer == phi


def test_trial_zero_of_a_design_file_is_that_design(small, tmp_path):
    """Tuning from a DESIGN.json evaluates that design as it is (common random numbers: its metrics
    are those of fte simulate at the same seed and paths), with a user's alpha kept."""
    from fte_casadi.sim import simulate

    plant, scenario, ts, _ = small
    own = design(ts, sample_time=scenario.dt, initial_state=scenario.x0, plant_spec=SPEC, alpha=0.5)
    res = tune(own, plant, scenario, trials=2, seed=5, paths=2, base_is_given=True)
    direct = simulate(
        own, plant, scenario, paths=2, seed=5, progress=False, record_paths=0, detect=False
    ).metrics
    m0 = res.records[0].metrics
    assert m0["fault_rel_rms_error"] == direct["fault_rel_rms_error"]
    assert m0["windows"] == direct["windows"]
    assert res.records[0].params["alpha"] == 0.5


def test_limits_named_when_no_candidate_helps(small):
    from fte_casadi.tune._search import _limits

    plant, _, _, base = small
    doc = base.to_json()

    def rec(k, ratios, fa):
        m = {"windows": [{"fault": "fa", "start": 1.5, "stop": 3.0, "ftc_true_ratio": ratios[0]},
                         {"fault": "fs", "start": 3.5, "stop": 5.0, "ftc_true_ratio": ratios[1]}],
             "false_alarm_peak": fa}  # fmt: skip
        return Record(k, {}, "ok", {}, m, doc, (0.0,))

    done = [rec(0, (1.2, 0.5), [0.3, 1.4]), rec(1, (1.1, 0.6), [0.2, 1.1])]
    lines = _limits(done, plant)
    # the fa window (no candidate below 1, the best is trial 1) and fs's false alarms (best 1.1)
    assert len(lines) == 2
    assert "best: trial 1" in lines[0] and "window of fa" in lines[0] and "FTC ratio 1.1" in lines[0]
    assert "false alarms of fs (ratio 1.1)" in lines[1]
    assert _limits([rec(0, (0.9, 0.5), [0.3, 0.4])], plant) == []


def test_bound_is_an_objective(result):
    """Issue #18 item 1: the certified bound enters the front as ``bound[fault_error]``, the certified L2
    gain max_k gain_k of each design's ``bounds.fault_error``; the rule ``bound`` takes the smallest."""
    names = result.objectives
    assert names[-1] == "bound[fault_error]"
    done = [r for r in result.records if r.state == "ok"]
    for r in done:
        gains = Design.from_dict(json.loads(r.design)).bounds["fault_error"]["gains"]
        assert r.values[-1] == r.metrics["fault_error_bound"] == max(gains.values()) > 0
    from fte_casadi.tune._search import _admissible

    k, _ = choose(list(result.records), list(result.front), names, "bound")
    front = [result.record(j) for j in result.front]
    tier = ([r for r in front if all(_admissible(r.metrics))] or [r for r in front if _admissible(r.metrics)[0]]
            or front)  # fmt: skip
    assert result.record(k).values[-1] == min(r.values[-1] for r in tier)


def test_choose_bound_rule():
    names = ("fault_error[f]", "bound[fault_error]")
    recs = [_rec(0, (0.2, 5.0)), _rec(1, (0.1, 7.0)), _rec(2, (0.3, 2.0))]
    assert choose(recs, [0, 1, 2], names, "bound")[0] == 2
    assert choose(recs, [0, 1, 2], names, "balanced")[0] == 1  # the bound is not in the balanced score


def _with_defaults(plant, **extra):
    import dataclasses

    return dataclasses.replace(plant, design_defaults=dict(plant.design_defaults) | extra)


def test_tuned_knobs_are_design_defaults(small):
    """Issue #18 item 3: alpha, kappa and the boundary layer a tune finds can be a plant's design defaults,
    so that a plain ``fte design PLANT`` makes the tuned design; an argument still wins."""
    from fte_casadi.errors import PlantError
    from fte_casadi.model import PlantBuilder

    plant, scenario, _, base = small
    a = 0.5 * base.observer.alpha
    ts = derive(_with_defaults(plant, alpha=a, kappa=3e3, boundary_layer=0.01))
    d = design(ts, sample_time=scenario.dt)
    assert d.certified and d.observer.alpha == a
    assert d.params.kappa == 3e3 and d.params.boundary_layer == 0.01
    assert d.checks["cond_Pbar"] <= 3e3 * 1.01
    assert any("from the plant's design defaults" in s for s in d.status)
    d2 = design(ts, sample_time=scenario.dt, alpha=0.25 * base.observer.alpha, kappa=1e4)
    assert d2.observer.alpha == 0.25 * base.observer.alpha and d2.params.kappa == 1e4
    b = PlantBuilder("p")
    with pytest.raises(PlantError, match="kappa"):
        b.design_defaults(kappa=0.5)
    with pytest.raises(PlantError, match="unknown parameter 'beta'"):
        b.design_defaults(beta=1.0)


def test_tune_from_tuned_defaults(small):
    """Trial 0 is the tuned default as it is; the candidates set alpha, kappa and the boundary layer from
    their own knobs, not from the plant's defaults."""
    plant, scenario, _, base = small
    a = 0.5 * base.observer.alpha
    tuned = _with_defaults(plant, alpha=a, kappa=3e3, boundary_layer=0.01)
    d = design(derive(tuned), sample_time=scenario.dt, initial_state=scenario.x0, plant_spec=SPEC)
    res = tune(d, tuned, scenario, trials=6, seed=3, paths=2)
    r0 = res.records[0]
    assert r0.params["alpha"] == a and r0.params["boundary_layer"] == 0.01 and r0.params["kappa"] == 3e3
    assert 0 < r0.knobs["alpha_scale"] < 1 and r0.knobs["use_boundary_layer"] and r0.knobs["kappa"] == 3e3
    ok = [r for r in res.records[1:] if r.state == "ok"]
    assert ok
    for r in ok:
        assert (r.params["boundary_layer"] is None) == (not r.knobs["use_boundary_layer"])
        assert r.params["alpha"] != a and r.params["kappa"] == pytest.approx(r.knobs["kappa"])


def test_three_tank_default_is_the_tuned_design():
    """Issue #18 item 3: the three-tank's default design (the tuned defaults) is better than the design at
    Section 6.2's parameters on every metric of the issue's table, on paths the tune did not see (seed 7)."""
    import dataclasses

    from fte_casadi.plants import SCENARIOS, three_tank
    from fte_casadi.sim import simulate

    plant, scenario = three_tank(), SCENARIOS["three-tank"]()
    paper = dataclasses.replace(plant, design_defaults=dict(gamma=1.0, gamma1=0.9, sigma=5.0, delta=1e-4,
                                                            epsilon=1e-4))  # fmt: skip
    m = {}
    for name, p in (("tuned", plant), ("paper", paper)):
        d = design(derive(p), sample_time=scenario.dt, initial_state=scenario.x0)
        assert d.certified
        m[name] = simulate(d, plant, scenario, paths=10, seed=7, progress=False, record_paths=0).metrics
    assert "boundary_layer" in plant.design_defaults and m["tuned"]["windows"][0]["fault"] == "fa"
    for key in ("fault_rel_rms_error", "false_alarm_peak"):
        assert m["tuned"][key][0] < m["paper"][key][0], key
    assert m["tuned"]["windows"][0]["ftc_true_ratio"] < m["paper"]["windows"][0]["ftc_true_ratio"]


def test_local_steps_are_one_knob_from_the_base(small):
    """The first trials after the base: each float knob times and divided by 2 within its range, then the
    boundary layer switched, then the bound's weight; none when the budget is short."""
    from fte_casadi.tune._space import LOCAL_FACTOR, LOCAL_SHARE, space_for

    _, _, _, base = small
    sp = space_for(base, None)
    steps = sp.local_steps(1000)
    assert steps and sp.local_steps(LOCAL_SHARE * len(steps) - 1) == []
    for st in steps[:-2]:
        changed = [k for k in sp.base if st[k] != sp.base[k]]
        assert len(changed) == 1 and changed[0] not in ("boundary_layer_rel", "use_boundary_layer", "bound_weight",
                                                        "use_bound_weight")  # fmt: skip
        k = changed[0]
        lo, hi = sp.ranges[k]
        assert lo <= st[k] <= hi
        assert st[k] / sp.base[k] in (pytest.approx(LOCAL_FACTOR), pytest.approx(1 / LOCAL_FACTOR)) or st[
            k
        ] in (lo, hi)
    assert steps[-2] == sp.base | {"use_boundary_layer": True}
    assert steps[-1] == sp.base | {"use_bound_weight": True} and sp.base["bound_weight"] == 1.0
    # alpha_scale is 1 at the base and at most 1: only its step down is taken
    assert sum(1 for st in steps if st["alpha_scale"] != 1.0) == 1
