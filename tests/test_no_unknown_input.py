"""A plant without unknown inputs, as a user writes one (the README's pendulum with d left out): it designs,
simulates (the engine had built a 1x0 block for the absent d) and --explore finds its certified designs (gamma
bounds nothing in (45) without a d block; the frontier had called every sigma infeasible)."""

from __future__ import annotations

import dataclasses

import casadi as ca
import numpy as np
import pytest

from fte_casadi import PlantBuilder
from fte_casadi.design import DesignOptions, augment, design, explore
from fte_casadi.design.core._diagnose import gamma_min, sigma_max
from fte_casadi.errors import ParameterError
from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, UniformNoise, simulate
from fte_casadi.ts import derive


def pendulum_without_d():
    b = PlantBuilder("pendulum_nod")
    th, om = b.states("theta", "omega", units=["rad", "rad/s"])
    (u,) = b.inputs("torque")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    b.drift([om, -9.81 * ca.sin(th) - 0.8 * om + 2.0 * (u + fa)])
    b.diffusion([0.0, 0.01 * om + 0.005 * ca.sin(th)])
    b.outputs([th + fs, om, th + om])
    b.region(theta=(-ca.pi, ca.pi), omega=(-4.0, 4.0))
    b.reference(u=[0.5])
    b.input_limits(torque=(-5.0, 5.0))
    return b.build()


def _scenario(T=4.0):
    return Scenario(name="nod", T=T, dt=1e-3, paths=2, x0_noise=0.01,
                    faults=(LossOfEffectiveness("fa", loss=0.3, start=1.0, stop=2.0),
                            Bias("fs", value=0.05, start=2.5, stop=3.5)),
                    measurement_noise=(0.002, 0.01, 0.003))  # fmt: skip


@pytest.fixture(scope="module")
def model():
    return derive(pendulum_without_d(), fidelity_samples=100)


def test_it_designs_and_simulates(model):
    plant = model.plant
    assert plant.ld == 0
    d = design(model, _scenario().design_options(DesignOptions()))
    assert d.certified
    m = simulate(d, plant, _scenario(), paths=2, seed=1, progress=False).metrics
    assert all(np.isfinite(v) for v in m["state_rms_error"]) and len(m["windows"]) == 2
    # without measurement noise as well: the calibration's engine had added a 1x0 to a 0x1 block for the absent d
    calm = dataclasses.replace(_scenario(), measurement_noise=None)
    m = simulate(d, plant, calm, paths=2, seed=1, progress=False, calibration_paths=20).metrics
    assert all(np.isfinite(e["threshold"]) for e in m["detection"]) and len(m["windows"]) == 2
    # a scenario that drives unknown inputs this plant does not have is refused, not run without them
    with pytest.raises(
        ParameterError, match=r"drives unknown inputs \(UniformNoise\) but plant 'pendulum_nod' has"
    ):
        simulate(d, plant, dataclasses.replace(_scenario(), unknown_input=UniformNoise(0.1)), paths=2, seed=1,
                 progress=False)  # fmt: skip


def test_gamma_bounds_nothing_and_the_frontier_finds_the_design(model):
    aug = augment(model.local_models, model.C, model.Df)
    sup, _ = sigma_max(aug, None, 0.1, "CLARABEL")
    assert sup is not None and sup > 0
    assert gamma_min(aug, 0.5 * sup, 0.1, "CLARABEL")[0] == 0.0  # any gamma
    assert gamma_min(aug, 2.0 * sup, 0.1, "CLARABEL")[0] is None  # beyond the bound of (45)
    points, info = explore(model, DesignOptions(sample_time=1e-3), count=4, budget=None)
    assert info["best"] is not None and info["best"].certified
    assert any(p.certified for p in points) and all(p.gamma_min in (0.0, None) for p in points)


def test_advice_keeps_the_options_given():
    o = DesignOptions(kappa=1e6, sigma=0.2, solver="scs", sample_time=1e-3)
    assert o.flags() == " --solver SCS --sigma 0.2 --kappa 1e+06"  # the sample time: the scenario's again
