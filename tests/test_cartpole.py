"""The textbook cart-pole at its 1 ms step (issue #21): the design is made for the rate the controller
runs at (the discrete step proven stable there), and simulate, codegen and the document agree on it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.codegen import default_sample_time
from fte_casadi.design import design
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.ts import derive

SPEC = str(Path(__file__).with_name("plant_cartpole.py")) + ":cartpole"


@pytest.fixture(scope="module")
def ts():
    from plant_cartpole import cartpole

    return derive(cartpole(), fidelity_samples=2000)


@pytest.mark.slow
def test_designs_at_its_1_ms_step_with_the_discrete_step_proven(ts, tmp_path):
    d = design(ts, sample_time=1e-3, plant_spec=SPEC)
    assert d.certified and d.observer.sample_time == 1e-3
    disc = d.checks["discrete"]
    assert disc["holds"] and disc["sample_time"] == 1e-3 and disc["ts_max_lyapunov"] > 1e-3
    f = tmp_path / "cp.json"
    d.save(f)
    assert default_sample_time(d) == 1e-3
    runner = CliRunner()
    r = runner.invoke(
        main, ["simulate", str(f), "--plant", SPEC, "--paths", "2", "--seed", "1", "--json", "--quiet"]
    )
    assert r.exit_code == 0, r.output
    m = json.loads(r.stdout)
    assert m["dt"] == 1e-3 and m["dt_change"] is None
    assert max(m["fault_rel_rms_error"]) < 0.5  # it estimates its faults at that rate
    r = runner.invoke(main, ["codegen", str(f), "--out", str(tmp_path / "c")])
    assert r.exit_code == 0, r.output
    assert "#define FTE_CARTPOLE_TS (0.001)" in (tmp_path / "c" / "fte_cartpole.h").read_text()


@pytest.mark.heavy
def test_a_rate_too_slow_is_refused_naming_one_that_works(ts):
    """At 100 ms no certified design of this plant runs: the refusal names a sample time that works, and a
    design at that sample time is certified. (At 50 ms Theorem 1's (29) certifies one, where (46) does not.)
    The manipulator's tests/test_sample_time.py checks the same in 7 s, this one takes 17: `pytest -m heavy`."""
    with pytest.raises(InfeasibleDesignError) as err:
        design(ts, sample_time=0.1, sigma=0.79)
    msg = " ".join(str(err.value).split())
    assert "no certified design runs at the sample time 0.1" in msg
    ts_ok = float(msg.split("Run the observer at a sample time <= ")[1].split(" ")[0])
    assert 0 < ts_ok < 0.1
    assert design(ts, sample_time=ts_ok, sigma=0.79).certified
