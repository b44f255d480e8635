"""Scenarios: fault profiles, unknown inputs, measurement noise, initial-state noise, horizon and step.

Everything is a frozen dataclass, validated once when it is made. A scenario is resolved
against a plant (fault names -> indices, the input an actuator fault acts on, the output a
sensor fault acts on) by :func:`fault_schedule`, which asks each fault profile for its rows
(:mod:`._fault_shapes`) and adds them into per-sample coefficients the compiled closed-loop sample
consumes::

    f_j(t_k) = a_j(t_k) + lu_j(t_k) * u_k[iu_j] + st_j(t_k) * (m_j - (C x_k)[k_j]) / Df[k_j, j]

``a`` carries biases and drifts, ``lu`` loss of effectiveness, ``st`` a stuck sensor, whose
remembered reading ``m_j`` is latched (``la_j = 1``) at the first sample of its window. The
unknown input and the measurement noise are models of :mod:`._noise`.
"""

from __future__ import annotations

import dataclasses
import json
from dataclasses import asdict, dataclass

import numpy as np

from ..errors import ParameterError
from ._fault_shapes import FAULT_SHAPES, FaultShape, FaultSite
from ._fault_shapes import Bias as Bias
from ._fault_shapes import Drift as Drift
from ._fault_shapes import LossOfEffectiveness as LossOfEffectiveness
from ._fault_shapes import Stuck as Stuck
from ._noise import (
    MEASUREMENT_NOISES,
    UNKNOWN_INPUTS,
    GaussianNoise,
    MeasurementNoise,
    UnknownInput,
    positive,
)
from ._noise import Sinusoid as Sinusoid
from ._noise import UniformNoise as UniformNoise

__all__ = [
    "LossOfEffectiveness",
    "Bias",
    "Stuck",
    "Drift",
    "UniformNoise",
    "Sinusoid",
    "Scenario",
    "FaultSchedule",
    "fault_schedule",
]


def _kinds(registry: dict) -> str:
    names = [c.__name__ for c in registry.values()]
    return ", ".join(names[:-1]) + " or " + names[-1] if len(names) > 1 else "".join(names)


def _model(value, base: type, registry: dict, what: str):
    """``value`` if it is a model of ``base`` (a dataclass instance), else a ParameterError naming the kinds."""
    if isinstance(value, base) and dataclasses.is_dataclass(value):
        return value
    raise ParameterError(f"unknown {what} {value!r}; use {_kinds(registry)} (or a dataclass subclass of "
                         f"{base.__name__})")  # fmt: skip


def _document(model) -> dict:
    return {**asdict(model), "kind": model.kind}


def _from_document(doc: dict, registry: dict, what: str):
    doc = dict(doc)
    kind = doc.pop("kind", None)
    if kind not in registry:
        raise ParameterError(
            f"a scenario document names the {what} kind {kind!r}, which is not defined here (the kinds are "
            f"{sorted(registry)}); import the module that defines it before reading the document"
        )
    return registry[kind](**doc)


@dataclass(frozen=True)
class Scenario:
    """A closed-loop experiment: faults, unknown inputs, initial state, horizon and step.

    Parameters
    ----------
    name : str
    T : float
        Horizon (in the plant's time unit).
    dt : float
        Default Euler-Maruyama step, which the simulated controller also samples at (see
        :mod:`fte_casadi.sim` for ``dt`` and ``sample_time``).
    faults : tuple
        Fault profiles (:class:`LossOfEffectiveness`, :class:`Bias`, :class:`Drift`, :class:`Stuck`, or
        any other :class:`~fte_casadi.sim._fault_shapes.FaultShape`).
    unknown_input : UniformNoise | Sinusoid | None
        A model of :class:`~fte_casadi.sim._noise.UnknownInput`; ``None``: d = 0.
    x0 : tuple or None
        Nominal initial state; ``None`` takes the plant's.
    x0_noise : float
        Standard deviation of the Gaussian noise added to x0, independently per path and state.
    paths : int
        Number of Brownian paths the paper uses (the default of ``fte simulate``).
    observer_init : str
        ``"nominal"``: z0 = [x0_nominal; 0; 0] - H y0, so that xhat starts at the nominal x0
        (what an engineer who knows x0 but not its noise does); ``"zero"``: z0 = 0.
    divergence_bound : float
        A path whose |x| exceeds this (or turns NaN/Inf) stops the run.
    measurement_noise : sequence of float, MeasurementNoise or None
        Standard deviation of white Gaussian noise added to each output at every step, in the output's
        units (one per output; 0 for a noiseless output), reproducible by seed: held as a
        :class:`~fte_casadi.sim._noise.GaussianNoise`; or another model of
        :class:`~fte_casadi.sim._noise.MeasurementNoise`. ``None``: no noise.
    """

    name: str
    T: float
    dt: float
    faults: tuple = ()
    unknown_input: UnknownInput | None = None
    x0: tuple | None = None
    x0_noise: float = 0.0
    paths: int = 5
    observer_init: str = "nominal"
    divergence_bound: float = 1e6
    measurement_noise: MeasurementNoise | None = None

    def __post_init__(self):
        positive("horizon T", self.T)
        positive("time step dt", self.dt)
        if self.dt > self.T:
            raise ParameterError(f"time step dt = {self.dt} is longer than the horizon T = {self.T}")
        positive("initial-state noise", self.x0_noise, allow_zero=True)
        positive("divergence bound", self.divergence_bound)
        if not isinstance(self.paths, int) or self.paths < 1:
            raise ParameterError(f"scenario paths must be a positive integer; got {self.paths!r}")
        if self.observer_init not in ("nominal", "zero"):
            raise ParameterError(f"observer_init must be 'nominal' or 'zero'; got {self.observer_init!r}")
        object.__setattr__(self, "faults", tuple(self.faults))
        for fp in self.faults:
            _model(fp, FaultShape, FAULT_SHAPES, "fault profile")
        if self.unknown_input is not None:
            _model(self.unknown_input, UnknownInput, UNKNOWN_INPUTS, "unknown-input model")
        if self.x0 is not None:
            object.__setattr__(self, "x0", tuple(float(v) for v in self.x0))
        mn = self.measurement_noise
        if mn is not None:
            if not isinstance(mn, MeasurementNoise):  # standard deviations per output
                mn = GaussianNoise(mn)
            mn = _model(mn, MeasurementNoise, MEASUREMENT_NOISES, "measurement-noise model")
            object.__setattr__(self, "measurement_noise", mn)

    def until(self, T: float) -> Scenario:
        """The same experiment over the shorter horizon ``T``: the fault windows that start before ``T``, each
        ending at ``T`` at the latest (a window must lie inside [0, T))."""
        from dataclasses import replace

        faults = tuple(replace(fp, stop=min(float(fp.stop), float(T))) for fp in self.faults if fp.start < T)
        return replace(self, T=float(T), faults=faults)

    def shortest_window(self) -> float | None:
        """The shortest fault window (None without faults): the observer must settle within it (three of its
        time constants; ``DesignOptions.settle_window``)."""
        return min((float(f.stop) - float(f.start) for f in self.faults), default=None)

    def design_options(self, options):
        """``options`` (a :class:`~fte_casadi.design.DesignOptions`) completed with what this scenario says of
        the design, where not given: the sample time (its step ``dt``, the controller's), the window the observer
        must settle in (:meth:`shortest_window`) and the nominal initial state."""
        changes = {}
        if options.sample_time is None:
            changes["sample_time"] = float(self.dt)
        if options.settle_window is None and self.faults:
            changes["settle_window"] = self.shortest_window()
        if options.initial_state is None and self.x0 is not None:
            changes["initial_state"] = self.x0
        return options.replace(**changes) if changes else options

    def windows(self, fault: str) -> list[tuple[float, float]]:
        """The (start, stop) windows of every profile acting on ``fault``."""
        return [(fp.start, fp.stop) for fp in self.faults if fp.fault == fault]

    # -- serialisation (embedded in result files) ---------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        d["faults"] = [_document(fp) for fp in self.faults]
        d["unknown_input"] = None if self.unknown_input is None else _document(self.unknown_input)
        mn = self.measurement_noise
        d["measurement_noise"] = None if mn is None else _document(mn)
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, doc: dict) -> Scenario:
        """The scenario of :meth:`to_dict` (a ``measurement_noise`` given as a list is Gaussian noise)."""
        doc = dict(doc)
        faults = tuple(_from_document(fp, FAULT_SHAPES, "fault shape") for fp in doc.pop("faults", []))
        ui = doc.pop("unknown_input", None)
        if ui is not None:
            ui = _from_document(ui, UNKNOWN_INPUTS, "unknown-input model")
        mn = doc.pop("measurement_noise", None)
        if isinstance(mn, dict):
            mn = _from_document(mn, MEASUREMENT_NOISES, "measurement-noise model")
        return cls(faults=faults, unknown_input=ui, measurement_noise=mn, **doc)


@dataclass(frozen=True)
class FaultSchedule:
    """Per-sample fault coefficients (see the module docstring); arrays of shape (steps, lf)."""

    a: np.ndarray
    lu: np.ndarray
    st: np.ndarray
    la: np.ndarray
    #: per fault: index of the input (actuator loss) and output (stuck sensor) involved, -1 if none
    input_index: tuple[int, ...]
    output_index: tuple[int, ...]
    #: per fault: the divisor Df[k, j] of a stuck sensor (1 otherwise)
    output_gain: tuple[float, ...]

    def stacked(self) -> np.ndarray:
        """(4 lf, steps): rows a, lu, st, la — the layout the compiled sample reads."""
        return np.concatenate([self.a, self.lu, self.st, self.la], axis=1).T.copy()


def fault_schedule(
    scenario: Scenario,
    fault_names,
    fault_kinds,
    B: np.ndarray,
    Bf: np.ndarray,
    Df: np.ndarray,
    input_names,
    t: np.ndarray,
    dt: float,
    u_operating: np.ndarray | None = None,
    u_ref: np.ndarray | None = None,
) -> FaultSchedule:
    """Resolve ``scenario``'s fault profiles against a plant and tabulate them at times ``t``.

    Each profile computes its rows from a :class:`~fte_casadi.sim._fault_shapes.FaultSite` (and refuses a
    fault it cannot act on); the rows of the profiles on one fault add up (``a``, ``lu``) or combine by
    "or" (``st``, ``la``). Profiles of one fault acting on different inputs or outputs are refused.
    """
    fault_names = list(fault_names)
    lf, steps = len(fault_names), len(t)
    a, lu, st, la = (np.zeros((steps, lf)) for _ in range(4))
    iu, ky, kg = [-1] * lf, [-1] * lf, [1.0] * lf
    for fp in scenario.faults:
        if fp.fault not in fault_names:
            raise ParameterError(
                f"scenario {scenario.name!r}: fault {fp.fault!r} is not a fault of the plant; its faults are {fault_names}"
            )
        j = fault_names.index(fp.fault)
        site = FaultSite(scenario.name, fp.fault, j, fault_kinds[j], B, Bf, Df, tuple(input_names), t, dt,
                         u_operating, u_ref)  # fmt: skip
        rows = fp.rows(site)
        for col, part in ((a, rows.a), (lu, rows.lu)):
            if part is not None:
                col[:, j] += part
        for col, part in ((st, rows.st), (la, rows.la)):
            if part is not None:
                col[:, j] = np.maximum(col[:, j], part)
        for what, idx, new in (("inputs", iu, rows.input_index), ("outputs", ky, rows.output_index)):
            if new >= 0 and idx[j] not in (-1, new):
                raise ParameterError(
                    f"scenario {scenario.name!r}: the profiles of fault {fp.fault!r} act on different {what} "
                    f"({idx[j]} and {new}); a fault acts through one input or one output"
                )
            if new >= 0:
                idx[j] = new
        if rows.output_index >= 0:
            kg[j] = float(rows.output_gain)
    return FaultSchedule(a, lu, st, la, tuple(iu), tuple(ky), tuple(kg))
