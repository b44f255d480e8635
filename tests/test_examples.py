"""Every example in examples/ runs, on a short horizon: the user plant through derive, design,
simulate and the generated C (compiled under the strict flags, equal to the Python step)."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from certified import assert_certified
from tolerances import C_DOUBLE, ROUNDOFF

from fte_casadi.codegen import CStep, closed_loop_compare, generate_c
from fte_casadi.codegen import _build as build
from fte_casadi.design import design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import metrics, simulate
from fte_casadi.ts import derive

EXAMPLES = Path(__file__).resolve().parents[1] / "examples"
#: every example plant: (spec, faults it estimates)
SPECS = [f"{EXAMPLES / 'pendulum_plant.py'}:pendulum", f"{EXAMPLES / 'pendulum_plain.py'}:pendulum",
         f"{EXAMPLES / 'bilinear_plant.py'}:bilinear"]  # fmt: skip
SPEC = SPECS[0]


@pytest.fixture(scope="module", params=SPECS, ids=["premise-form", "plain-sin", "bilinear-tanh"])
def pendulum_design(request):
    ts = derive(load_plant(request.param))
    assert ts.fidelity.max_abs_error <= ROUNDOFF
    return design(ts, plant_spec=request.param, sample_time=load_scenario(request.param).dt)


def test_every_example_is_tested():
    """Each plant file in examples/ is in SPECS (examples/embedded/ has its own test module)."""
    assert {p.name for p in EXAMPLES.glob("*.py")} == {Path(s.split(":")[0]).name for s in SPECS}


def test_example_design_is_certified(pendulum_design):
    d = pendulum_design
    assert d.certified
    assert max(d.checks["lmi_max_eig"].values()) < 0
    assert d.checks["R_max_real_eig"] < 0 and d.checks["closed_loop_max_real_eig"] < 0


@pytest.mark.slow
def test_example_simulates_and_estimates_its_faults(pendulum_design):
    spec = pendulum_design.plant_spec
    sc = load_scenario(spec)
    res = simulate(pendulum_design, load_plant(spec), sc, paths=4, seed=3, progress=False)
    m = metrics(res)
    assert m["paths"] == 4
    # both faults are estimated and tolerant control reduces the output deviation
    assert all(e is not None and e < 0.5 for e in m["fault_rel_rms_error"])
    assert m["ftc_true_ratio"] < 0.8
    short = sc.until(1.0)
    assert simulate(pendulum_design, load_plant(spec), short, paths=2, seed=0, progress=False).t[
        -1
    ] == pytest.approx(1.0)


@pytest.mark.slow
@pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")
def test_example_generated_c_equals_python(pendulum_design, tmp_path):
    d = pendulum_design
    sample_time = 1e-3
    generate_c(d, tmp_path / "c", sample_time=sample_time)
    lib = build.compile_shared(tmp_path / "c", tmp_path / "libpendulum.so")

    def fault(t, u):
        f = np.array([-0.3 * u[0] if t > 0.5 else 0.0, 0.05 if t > 1.0 else 0.0])
        return f[: int(d.dims.lf)]

    err, traj = closed_loop_compare(
        d, CStep(lib, d), sample_time, 1500, plant=load_plant(d.plant_spec), fault=fault
    )
    assert max(err.values()) <= C_DOUBLE
    assert np.max(np.abs(traj["fhat"][-1])) > 0.01  # the observer saw the faults


@pytest.mark.slow
def test_example_runs_from_the_command_line(tmp_path):
    p = subprocess.run(
        [sys.executable, "-m", "fte_casadi", "design", SPEC, "-o", str(tmp_path / "p.json")],
        capture_output=True,
        text=True,
        timeout=300,
        cwd=tmp_path,
    )
    assert p.returncode == 0, p.stderr
    assert_certified(p.stdout, tmp_path / "p.json")
