"""Fault shapes and noise models are objects: a new one is one class, defined here alone, and simulated."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np
import pytest

from fte_casadi.errors import ParameterError
from fte_casadi.sim import (
    Bias,
    FaultRows,
    FaultShape,
    GaussianNoise,
    LossOfEffectiveness,
    MeasurementNoise,
    Scenario,
    Stuck,
    UniformNoise,
    UnknownInput,
    UnknownInputTerms,
    simulate,
)
from fte_casadi.sim._engine import plant_schedule
from fte_casadi.sim._fault_shapes import FAULT_SHAPES
from fte_casadi.sim._noise import MEASUREMENT_NOISES, UNKNOWN_INPUTS


@dataclass(frozen=True)
class IntermittentBias(FaultShape, kind="test_intermittent_bias", label="intermittent bias"):
    """A bias of ``value`` that is on for the first ``duty`` of every ``period`` in ``[start, stop)``."""

    fault: str
    value: float
    period: float
    duty: float
    start: float
    stop: float

    def validate(self):
        if not (0.0 < self.duty < 1.0):
            raise ParameterError(f"intermittent bias: duty must lie in (0, 1); got {self.duty!r}")
        if not self.period > 0:
            raise ParameterError(f"intermittent bias: period must be positive; got {self.period!r}")

    def rows(self, site):
        on = site.active(self.start, self.stop)
        phase = np.mod(site.t - self.start + 1e-9 * site.dt, self.period)
        a = site.zeros()
        a[on & (phase < self.duty * self.period)] = self.value
        return FaultRows(a=a)


@dataclass(frozen=True)
class StepInput(UnknownInput, kind="test_step_input"):
    """Unknown input 0 before ``at``, ``height`` from then on (deterministic)."""

    height: float
    at: float

    def terms(self, t, scale):
        return UnknownInputTerms(deterministic=scale * self.height * (t >= self.at))


@dataclass(frozen=True)
class NoiseBurst(MeasurementNoise, kind="test_noise_burst"):
    """Gaussian noise of ``std`` on every output from ``at`` on, none before."""

    std: float
    at: float
    outputs: int

    def deviations(self, t, scale):
        return np.repeat((scale * self.std * (t >= self.at))[None, :], self.outputs, axis=0)

    def reported(self, scale):
        return [scale * self.std] * self.outputs


T, DT = 1.0, 1e-3
PULSE = IntermittentBias("fa", value=0.5, period=0.2, duty=0.25, start=0.2, stop=0.8)


def _scenario(**kw) -> Scenario:
    base = dict(name="shapes", T=T, dt=DT, faults=(PULSE,), unknown_input=UniformNoise(0.05),
                x0=(0.1, 0.05, 0.02, 0.03))  # fmt: skip
    return Scenario(**{**base, **kw})


def _expected_pulse(t: np.ndarray) -> np.ndarray:
    """The intermittent bias written out independently: on in [0.2, 0.25), [0.4, 0.45), [0.6, 0.65)."""
    k = np.rint(t / DT).astype(int)
    on = np.zeros(len(t), bool)
    for a in (200, 400, 600):
        on |= (k >= a) & (k < a + 50)
    return np.where(on, 0.5, 0.0)


def test_subclassing_registers_the_shape_and_its_document_round_trips():
    assert FAULT_SHAPES["test_intermittent_bias"] is IntermittentBias
    assert FAULT_SHAPES["bias"] is Bias and FAULT_SHAPES["loss"] is LossOfEffectiveness
    sc = _scenario(measurement_noise=[0.01, 0.0, 0.02])
    doc = sc.to_dict()
    assert doc["faults"][0]["kind"] == "test_intermittent_bias"
    assert doc["measurement_noise"] == {"std": (0.01, 0.0, 0.02), "kind": "gaussian"}
    back = Scenario.from_dict(doc)
    assert back == sc and isinstance(back.faults[0], IntermittentBias)
    assert back.measurement_noise == GaussianNoise((0.01, 0.0, 0.02))
    # a document written with the measurement noise as a plain list reads as Gaussian noise
    assert Scenario.from_dict({**doc, "measurement_noise": [0.01, 0.0, 0.02]}) == sc


def test_a_shape_validates_itself():
    with pytest.raises(ParameterError, match="duty must lie in"):
        IntermittentBias("fa", value=0.5, period=0.2, duty=1.5, start=0.2, stop=0.8)
    with pytest.raises(ParameterError, match="intermittent bias: the window must have start < stop"):
        IntermittentBias("fa", value=0.5, period=0.2, duty=0.5, start=0.8, stop=0.2)
    with pytest.raises(ParameterError, match="loss of effectiveness must lie in"):
        LossOfEffectiveness("fa", loss=1.5, start=0.0, stop=1.0)


def test_registry_refusals():
    with pytest.raises(TypeError, match="kind 'bias' is taken"):

        @dataclass(frozen=True)
        class OtherBias(FaultShape, kind="bias"):
            fault: str
            start: float
            stop: float

    assert FAULT_SHAPES["bias"] is Bias
    with pytest.raises(ParameterError, match="unknown fault profile 'bias'; use .*IntermittentBias"):
        Scenario(name="x", T=1.0, dt=0.1, faults=("bias",))
    with pytest.raises(ParameterError, match="unknown unknown-input model"):
        Scenario(name="x", T=1.0, dt=0.1, unknown_input=0.1)
    doc = _scenario().to_dict()
    doc["faults"][0]["kind"] = "no_such_shape"
    with pytest.raises(ParameterError, match="fault shape kind 'no_such_shape'.*import the module"):
        Scenario.from_dict(doc)
    assert UNKNOWN_INPUTS["test_step_input"] is StepInput
    assert MEASUREMENT_NOISES["test_noise_burst"] is NoiseBurst


def test_the_schedule_takes_the_shapes_rows(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    t = np.arange(int(round(T / DT)) + 1) * DT
    sc = _scenario(faults=(PULSE, Bias("fa", 0.25, 0.5, 0.7), Stuck("fs", 0.3, 0.6)))
    sched = plant_schedule(design, plant, sc, t, DT)
    ja, js = plant.fault_names.index("fa"), plant.fault_names.index("fs")
    k = np.arange(len(t))
    bias = np.where((k >= 500) & (k < 700), 0.25, 0.0)
    np.testing.assert_array_equal(sched.a[:, ja], _expected_pulse(t) + bias)
    assert np.all(sched.lu == 0) and np.all(sched.a[:, js] == 0)
    assert sched.st[:, js].sum() == 300 and np.flatnonzero(sched.la[:, js]).tolist() == [300]
    with pytest.raises(ParameterError, match="needs a sensor fault"):
        plant_schedule(design, plant, _scenario(faults=(Stuck("fa", 0.3, 0.6),)), t, DT)


def test_a_new_shape_is_simulated(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    kw = dict(paths=2, seed=3, progress=False, record_all=True, record_every=1, detect=False)
    r = simulate(design, plant, _scenario(), **kw)
    j = plant.fault_names.index("fa")
    want = _expected_pulse(r.t)
    assert np.all(r.free.f == 0)
    for run in (r.no_ftc, r.ftc):
        np.testing.assert_array_equal(run.f[:, :, j], np.broadcast_to(want, run.f.shape[:2]))
    # the fault acts on the plant: the tolerant faulty run leaves the fault-free one (the same controller and
    # noise) at the first pulse, not before
    dev = np.abs(r.ftc.x - r.free.x).max(axis=(0, 2))
    assert dev[:201].max() == 0 and dev[201:260].max() > 0
    half = simulate(design, plant, _scenario(), scales={"fault_scale": 0.5}, **kw)
    np.testing.assert_array_equal(half.no_ftc.f[:, :, j], 0.5 * r.no_ftc.f[:, :, j])


def test_new_noise_models_are_simulated(plants, lqr_designs):
    plant, design = plants["manipulator"], lqr_designs["manipulator"]
    kw = dict(paths=2, seed=5, progress=False, record_all=True, record_every=1, detect=False)
    quiet = simulate(design, plant, _scenario(faults=(), unknown_input=None), **kw)
    step = simulate(design, plant, _scenario(faults=(), unknown_input=StepInput(0.3, at=0.4)), **kw)
    dev = np.abs(step.free.x - quiet.free.x).max(axis=(0, 2))
    assert dev[:401].max() == 0 and dev[401:].max() > 1e-6  # d enters from t = 0.4 on (the state after)
    burst = _scenario(
        faults=(), unknown_input=None, measurement_noise=NoiseBurst(0.01, at=0.5, outputs=plant.p)
    )
    b = simulate(design, plant, burst, **kw)
    v = b.free.y - b.free.x @ np.asarray(plant.C).T
    assert np.all(v[:, :500] == 0)
    assert 0.007 < v[:, 500:].std() < 0.013
    assert b.metrics["measurement_noise"] == [0.01] * plant.p
    with pytest.raises(ParameterError, match="measurement_noise has 2 entries; the plant has 3 outputs"):
        simulate(design, plant, dataclasses.replace(burst, measurement_noise=(0.1, 0.1)), **kw)
