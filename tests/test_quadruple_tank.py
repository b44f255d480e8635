"""The quadruple tank (issue #17 item 4, issue #21): a built-in plant whose numbers are nowhere near
one (time constants of 20-60 s, B entries 0.03-0.08), written as the physics reads.

It derives automatically, designs at the tool's own parameters with either solver, and its C,
started from the first measurement, shows no false fault estimate during start-up."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fte_casadi.codegen import CStep
from fte_casadi.codegen import _build as build
from fte_casadi.design import Design, design
from fte_casadi.design.core._certify import failures
from fte_casadi.plants import SCENARIOS, quadruple_tank
from fte_casadi.ts import derive

GENERATED = Path(__file__).resolve().parents[1] / "generated" / "quadruple_tank"


@pytest.fixture(scope="module")
def ts():
    return derive(quadruple_tank(), fidelity_samples=2000)


@pytest.fixture(scope="module")
def committed():
    return Design.load(GENERATED / "design.json")


def test_premises_found_automatically_and_exact(ts):
    assert ts.r == 16 and len(ts.premises) == 4
    assert all("sqrt" in p.expr for p in ts.premises)
    assert ts.fidelity.drift_max_abs_error < 1e-12


@pytest.mark.slow
def test_designs_at_its_own_parameters(ts):
    """No design defaults: the generic ones fail, and the tool finds sigma and gamma itself (and says so)."""
    assert not quadruple_tank().design_defaults
    d = design(ts, sample_time=SCENARIOS["quadruple-tank"]().dt)
    assert d.certified and not failures(d.checks)
    assert set(d.params_chosen) == {"sigma", "gamma"}
    for k, c in d.params_chosen.items():
        assert getattr(d.params, k) == c["value"]
        assert "first value tried that gives a certified design" in c["why"]
    # the generic default sigma = 1 is four orders of magnitude above what (45) allows for this plant
    assert d.params.sigma < 1e-3 and d.params.gamma > 1.0
    assert d.checks["discrete"]["holds"]


@pytest.mark.slow
@pytest.mark.heavy  # test_design.py::test_clarabel_and_scs_give_the_same_design checks it on two plants in seconds
def test_certifies_with_scs_too(ts, committed):
    """The same parameters with the other solver: certified, and the same observer up to the solvers'
    tolerance (the centred point is unique; only where it is found from differs)."""
    d = design(ts, solver="SCS", sigma=committed.params.sigma, gamma=committed.params.gamma,
               sample_time=SCENARIOS["quadruple-tank"]().dt)  # fmt: skip
    assert d.certified
    assert np.allclose(d.Pbar, committed.Pbar, rtol=1e-5, atol=1e-8 * np.abs(committed.Pbar).max())


@pytest.mark.slow
@pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler")
def test_c_started_from_the_first_measurement_has_no_false_fault_estimate(committed, tmp_path):
    """The committed C on the nonlinear plant. (1) With noise and the unknown inflow, the plant starting at
    the nominal state the design records: started with init_from_y, the fault estimates of the first
    100 s stay within the steady-state noise level (300-400 s) of the same fault-free run. (2) Without
    noise, the plant starting 2 cm away from the operating point and the C told so (init_from_y's xbar0):
    no start-up transient at all, while the same run started from z = 0 (init(NULL)) estimates faults
    of the size of the faults themselves."""
    d = committed
    lib = build.compile_shared(GENERATED, tmp_path / "libq.so")
    plant = quadruple_tank()
    F, G = plant.drift_function(), plant.diffusion_function()
    sample_time, n, lf, nd2 = 0.1, plant.n, plant.lf, plant.d2.shape[0]

    def run(x_start, seconds: float, *, start_from_y: bool = True, noise: bool = True, seed: int = 3):
        rng = np.random.default_rng(seed)
        c = CStep(lib, d)
        x = np.array(x_start, dtype=float)
        if start_from_y:
            assert c.init_from_y(np.asarray(d.C) @ x, np.concatenate([x, np.zeros(2 * lf)])) == 0
        else:
            c.init(None)
        fhat = []
        for _ in range(int(round(seconds / sample_time))):
            rc, u, xb, _ = c.step(np.asarray(d.C) @ x)
            assert rc == 0
            fhat.append(np.abs(xb[n + lf :]))
            dd = rng.uniform(-0.5, 0.5, size=plant.ld) if noise else np.zeros(plant.ld)
            dw = rng.normal(0.0, np.sqrt(sample_time)) if noise else 0.0
            x = (x + sample_time * np.asarray(F(x, u, dd, np.zeros(lf))).ravel()
                 + np.asarray(G(x, u, np.zeros(lf), np.zeros(nd2))).ravel() * dw)  # fmt: skip
        return np.array(fhat)

    np.testing.assert_array_equal(d.x0, np.zeros(n))  # the nominal start: the operating point
    fhat = run(d.x0, 400.0)
    level = fhat[3000:].max(axis=0)
    assert np.all(fhat[:1000].max(axis=0) <= level), (fhat[:1000].max(axis=0), level)

    away = [2.0, -1.5, 0.5, -0.4]
    steady = run(away, 400.0, noise=False)[3000:].max(axis=0)  # the model's own steady residue
    warm = run(away, 100.0, noise=False).max(axis=0)
    cold = run(away, 100.0, noise=False, start_from_y=False).max(axis=0)
    assert np.all(warm <= 1.25 * steady), (warm, steady)  # the residue moves a little with the state
    assert np.all(cold > 20 * steady), (cold, steady)


@pytest.mark.slow
def test_a_design_with_chosen_parameters_keeps_the_plant_and_start(ts):
    """The parameter search redesigns; the document it returns still names the plant (so that
    `fte simulate DESIGN.json` finds it) and the nominal start it was asked for."""
    x0 = (0.5, -0.5, 0.1, -0.1)
    d = design(ts, sample_time=0.1, plant_spec="quadruple-tank", initial_state=x0)
    assert d.params_chosen and d.plant_spec == "quadruple-tank"
    np.testing.assert_array_equal(d.x0, x0)
