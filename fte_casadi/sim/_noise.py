"""Unknown-input and measurement-noise models: each validates itself and gives the engine its terms.

The compiled engine draws, per path and step, a uniform number in [-1, 1] per entry of the unknown
input d and a standard normal number per output; a model says how to scale and shift them:

- an unknown-input model (:class:`UnknownInput`) gives :class:`UnknownInputTerms`: the half-width of
  the uniform draw and a deterministic signal added to it, ``d_k = uniform * U_k + deterministic(t_k)``;
- a measurement-noise model (:class:`MeasurementNoise`) gives the standard deviation of each output's
  noise at each sample, ``v_k = deviations(t_k) * N_k``, added to ``y = C x``.

Subclassing registers a model under its ``kind`` (its name in scenario documents), so a new model is
one frozen dataclass. The terms are proportional to the ``scale`` passed (a sweep rescales them).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import ParameterError

__all__ = [
    "UnknownInput",
    "UnknownInputTerms",
    "UniformNoise",
    "Sinusoid",
    "MeasurementNoise",
    "GaussianNoise",
]

#: the unknown-input models by ``kind``: filled by subclassing :class:`UnknownInput`
UNKNOWN_INPUTS: dict[str, type[UnknownInput]] = {}
#: the measurement-noise models by ``kind``: filled by subclassing :class:`MeasurementNoise`
MEASUREMENT_NOISES: dict[str, type[MeasurementNoise]] = {}


def positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    """``value`` as a float, refused unless finite and positive (or zero with ``allow_zero``)."""
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number; got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ParameterError(f"{name} must be a {kind} finite number; got {value!r}")
    return v


def _register(registry: dict, what: str, cls: type, kind: str | None) -> None:
    if kind is None:  # an intermediate base class
        return
    if not isinstance(kind, str) or not kind:
        raise TypeError(f"{cls.__name__}: kind must be a non-empty string; got {kind!r}")
    old = registry.get(kind)
    if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
        raise TypeError(f"{cls.__name__}: the {what} kind {kind!r} is taken by {old.__module__}.{old.__qualname__}; "
                        "choose another kind")  # fmt: skip
    cls.kind = kind
    registry[kind] = cls


@dataclass(frozen=True)
class UnknownInputTerms:
    """What the engine adds to the unknown input d at each sample: ``uniform * U + deterministic``.

    ``uniform``: half-width of the draw, uniform in [-uniform, uniform] per entry of d and per step,
    path and run alike; ``deterministic``: None (zero), one value per sample (the same on every entry),
    or an array (entries of d, samples).
    """

    uniform: float = 0.0
    deterministic: np.ndarray | None = None


class UnknownInput:
    """Base class of the unknown-input models: a frozen dataclass subclass with ``kind="..."``."""

    kind: ClassVar[str]

    def __init_subclass__(cls, kind: str | None = None, **kw):
        super().__init_subclass__(**kw)
        _register(UNKNOWN_INPUTS, "unknown-input", cls, kind)

    def terms(self, t: np.ndarray, scale: float) -> UnknownInputTerms:
        """The terms at sample times ``t``, multiplied by ``scale`` (the run's ``d_scale``)."""
        raise NotImplementedError(f"{type(self).__name__} does not define terms()")


@dataclass(frozen=True)
class UniformNoise(UnknownInput, kind="uniform"):
    """Unknown input drawn afresh each simulation step, uniform in ``[-amplitude, amplitude]``
    independently per entry of d (the paper's "d uniform in [-0.1, 0.1]")."""

    amplitude: float

    def __post_init__(self):
        positive("unknown-input amplitude", self.amplitude, allow_zero=True)

    def terms(self, t: np.ndarray, scale: float) -> UnknownInputTerms:
        return UnknownInputTerms(uniform=float(self.amplitude) * scale)


@dataclass(frozen=True)
class Sinusoid(UnknownInput, kind="sinusoid"):
    """Deterministic unknown input ``amplitude * sin(2 pi frequency t + phase)`` on every entry of d."""

    amplitude: float
    frequency: float
    phase: float = 0.0

    def __post_init__(self):
        positive("sinusoid amplitude", self.amplitude, allow_zero=True)
        positive("sinusoid frequency", self.frequency, allow_zero=True)

    def terms(self, t: np.ndarray, scale: float) -> UnknownInputTerms:
        return UnknownInputTerms(
            deterministic=scale * self.amplitude * np.sin(2 * np.pi * self.frequency * t + self.phase)
        )


class MeasurementNoise:
    """Base class of the measurement-noise models: a frozen dataclass subclass with ``kind="..."``."""

    kind: ClassVar[str]

    def __init_subclass__(cls, kind: str | None = None, **kw):
        super().__init_subclass__(**kw)
        _register(MEASUREMENT_NOISES, "measurement-noise", cls, kind)

    def check(self, scenario: str, output_names) -> None:
        """Refuse a model that does not fit the plant's outputs (raise ParameterError)."""

    def deviations(self, t: np.ndarray, scale: float) -> np.ndarray:
        """Standard deviation of each output's noise at sample times ``t``, times ``scale``: an array
        (outputs, samples), or (outputs, 1) when constant."""
        raise NotImplementedError(f"{type(self).__name__} does not define deviations()")

    def reported(self, scale: float) -> list[float]:
        """The standard deviation per output the metrics document reports (``measurement_noise``)."""
        raise NotImplementedError(f"{type(self).__name__} does not define reported()")


@dataclass(frozen=True)
class GaussianNoise(MeasurementNoise, kind="gaussian"):
    """White Gaussian noise of standard deviation ``std[k]`` on output k at every step, in the output's
    units (0 for a noiseless output). A scenario's ``measurement_noise=[...]`` is this model."""

    std: tuple

    def __post_init__(self):
        try:
            std = tuple(float(v) for v in self.std)
        except (TypeError, ValueError, AttributeError):
            raise ParameterError(
                f"measurement_noise must be a list of standard deviations, one per output; got {self.std!r}"
            ) from None
        for k, v in enumerate(std):
            positive(f"measurement_noise[{k}]", v, allow_zero=True)
        object.__setattr__(self, "std", std)

    def check(self, scenario: str, output_names) -> None:
        names = list(output_names)
        if len(self.std) != len(names):
            raise ParameterError(
                f"scenario {scenario!r}: measurement_noise has {len(self.std)} entries; the plant has {len(names)} "
                f"outputs ({', '.join(names)}): give one standard deviation per output, in the output's units"
            )

    def deviations(self, t: np.ndarray, scale: float) -> np.ndarray:
        return (np.asarray(self.std, dtype=float) * scale)[:, None]

    def reported(self, scale: float) -> list[float]:
        return [float(v) * scale for v in self.std]
