"""The certified bound on the fault-estimation error (issue #18 item 1): recorded in the design
document, and Monte Carlo on the nonlinear plant stays below it."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.design import design
from fte_casadi.design.bounds import bound_value
from fte_casadi.design.record import Design
from fte_casadi.plants.loader import load_plant, load_scenario
from fte_casadi.sim import Sinusoid, UniformNoise, simulate
from fte_casadi.ts import derive

SMALL = f"{Path(__file__).parent / 'plant_tune.py'}:plant"


def _energies(d, scenario) -> dict:
    """Upper bounds of E int_0^T |w_k|^2 dt per channel for a fault-free scenario."""
    T, ld, lf = scenario.T, int(d.dims["ld"]), int(d.dims["lf"])
    ui = scenario.unknown_input
    amp = 0.0 if ui is None else float(ui.amplitude)
    assert ui is None or isinstance(ui, (UniformNoise, Sinusoid))
    gain = float(d.params["delta"]) + float(d.params["epsilon"])
    return {"d": amp**2 * ld * T, "fddot": 0.0, "u_s": gain**2 * lf * T, "f": 0.0, "const": T}


@pytest.mark.parametrize("spec, horizon", [(SMALL, None), ("manipulator", None), ("three-tank", 100.0)])
def test_monte_carlo_stays_below_the_bound(spec, horizon):
    plant, scenario = load_plant(spec), load_scenario(spec)
    scenario = dataclasses.replace(scenario, faults=(), T=horizon or scenario.T)
    d = design(derive(plant), sample_time=scenario.dt, initial_state=scenario.x0)
    fb = d.bounds["fault_error"]
    assert fb["holds"] and fb["lmi_max_eig"] < 0
    assert Design.from_dict(json.loads(d.to_json())).bounds == json.loads(json.dumps(d.bounds))
    res = simulate(d, plant, scenario, paths=8, seed=4, progress=False, record_all=True, record_every=1)
    n, lf, dt = int(d.dims["n"]), int(d.dims["lf"]), res.dt
    run = res.ftc
    err = run.f - run.xbarhat[:, :, n + lf :]
    lhs = float(np.mean(np.sum(err[:, :-1, :] ** 2, axis=(1, 2)) * dt))
    xbar0 = np.concatenate([run.x[:, 0, :], np.zeros((run.x.shape[0], lf)), run.f[:, 0, :]], axis=1)
    xi0 = np.concatenate([run.x[:, 0, :], xbar0 - run.xbarhat[:, 0, :]], axis=1)
    P = np.asarray(fb["P"])
    v0 = float(np.mean(np.einsum("pi,ij,pj->p", xi0, P, xi0)))
    rhs = bound_value(fb, _energies(d, scenario), v0)
    assert 0 < lhs <= rhs, (lhs, rhs)
