"""Fault shapes: each profile validates itself and computes its own rows of the fault schedule.

A fault shape is a frozen dataclass subclassing :class:`FaultShape` with a ``kind`` (its name in
scenario documents) and at least the fields ``fault`` (the plant's fault it acts on), ``start`` and
``stop`` (the window ``start <= t < stop`` in which it acts, which the metrics and figures use). It
computes, from the plant data of :class:`FaultSite`, its contribution :class:`FaultRows` to the
schedule the compiled closed-loop sample reads (:mod:`._scenario`)::

    f_j(t_k) = a_j(t_k) + lu_j(t_k) * u_k[iu_j] + st_j(t_k) * (m_j - (C x_k)[k_j]) / Df[k_j, j]

Subclassing registers the shape, so a new shape is one class::

    @dataclass(frozen=True)
    class Pulse(FaultShape, kind="pulse"):
        fault: str
        value: float
        start: float
        stop: float

        def rows(self, site):
            a = site.zeros()
            a[site.active(self.start, self.stop)] = self.value
            return FaultRows(a=a)

A scenario document names the shape by its ``kind``; reading it back needs the class defined (its
module imported), on a cluster's workers too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from ..errors import ParameterError

__all__ = ["FaultShape", "FaultSite", "FaultRows", "LossOfEffectiveness", "Bias", "Drift", "Stuck"]

#: the fault shapes by ``kind``: filled by subclassing :class:`FaultShape`
FAULT_SHAPES: dict[str, type[FaultShape]] = {}


def window(label: str, start: float, stop: float) -> None:
    """Refuse a window that is not finite or not ``start < stop``, naming the shape."""
    for nm, v in (("start", start), ("stop", stop)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise ParameterError(f"{label}: {nm} must be a finite number; got {v!r}")
    if not start < stop:
        raise ParameterError(f"{label}: the window must have start < stop; got [{start}, {stop})")


@dataclass(frozen=True)
class FaultSite:
    """What a shape computes its rows from: its fault resolved against the plant, and the sample times.

    ``B``, ``Bf`` are the input and fault matrices of the design's first local model, ``Df`` the
    plant's; ``index`` is the fault's column in ``Bf``/``Df``; ``u_operating`` is the operating-point
    input of a plant written in deviations (None otherwise), ``u_ref`` the design's reference input.
    """

    scenario: str
    fault: str
    index: int
    kind: str
    B: np.ndarray
    Bf: np.ndarray
    Df: np.ndarray
    input_names: tuple[str, ...]
    t: np.ndarray
    dt: float
    u_operating: np.ndarray | None = None
    u_ref: np.ndarray | None = None

    def active(self, start: float, stop: float) -> np.ndarray:
        """The samples with ``start <= t < stop`` (a sample within 1e-9 dt of ``start`` counts as at it)."""
        eps = 1e-9 * self.dt
        return (self.t >= start - eps) & (self.t < stop - eps)

    def zeros(self) -> np.ndarray:
        """A row of zeros, one per sample."""
        return np.zeros(len(self.t))


@dataclass(frozen=True)
class FaultRows:
    """One profile's part of its fault's columns of the schedule (one value per sample; None: none).

    ``a`` and ``lu`` of several profiles on one fault add up; ``st`` and ``la`` are 0/1 marks and
    combine by "or". ``input_index`` names the input a loss scales (``lu``), ``output_index`` and
    ``output_gain`` the output a held sensor acts on and its ``Df`` entry (``st``, ``la``); -1: none.
    """

    #: additive fault: bias, drift, the operating-point part of a loss
    a: np.ndarray | None = None
    #: coefficient of the input ``u[input_index]``: a loss of effectiveness
    lu: np.ndarray | None = None
    #: 1 while the sensor's reading is held at its latched value
    st: np.ndarray | None = None
    #: 1 at the samples the held reading is latched
    la: np.ndarray | None = None
    input_index: int = -1
    output_index: int = -1
    output_gain: float = 1.0


class FaultShape:
    """Base class of the fault shapes; a subclass is registered under its ``kind``.

    Subclass it as a frozen dataclass with ``kind="..."`` in the class statement and the fields
    ``fault``, ``start``, ``stop`` (plus its own). Override :meth:`rows`, and :meth:`validate` for
    checks of its own fields (the window is checked here), :meth:`check_scale` when a
    ``fault_scale`` can make it meaningless.
    """

    #: the shape's name in scenario documents
    kind: ClassVar[str]
    #: the shape's name in messages (default: ``kind``)
    label: ClassVar[str]

    def __init_subclass__(cls, kind: str | None = None, label: str | None = None, **kw):
        super().__init_subclass__(**kw)
        if kind is None:  # an intermediate base class, not a shape
            return
        if not isinstance(kind, str) or not kind:
            raise TypeError(f"{cls.__name__}: kind must be a non-empty string; got {kind!r}")
        old = FAULT_SHAPES.get(kind)
        if old is not None and (old.__module__, old.__qualname__) != (cls.__module__, cls.__qualname__):
            raise TypeError(
                f"{cls.__name__}: the fault shape kind {kind!r} is taken by {old.__module__}.{old.__qualname__}; "
                "choose another kind"
            )
        cls.kind = kind
        cls.label = label or kind
        FAULT_SHAPES[kind] = cls

    def __post_init__(self) -> None:
        missing = [a for a in ("fault", "start", "stop") if not hasattr(self, a)]
        if missing:
            raise TypeError(f"{type(self).__name__}: a fault shape needs the fields fault, start and stop; "
                            f"it lacks {', '.join(missing)}")  # fmt: skip
        window(self.label, self.start, self.stop)
        self.validate()

    def validate(self) -> None:
        """Refuse invalid fields of the shape's own (raise :class:`~fte_casadi.errors.ParameterError`)."""

    def check_scale(self, fault_scale: float) -> None:
        """Refuse a ``fault_scale`` (which multiplies ``a``, ``lu``, ``st``) that makes the profile meaningless."""

    def rows(self, site: FaultSite) -> FaultRows:
        """The profile's rows at the sample times of ``site``; refuse a fault it cannot act on."""
        raise NotImplementedError(f"{type(self).__name__} does not define rows()")


@dataclass(frozen=True)
class LossOfEffectiveness(FaultShape, kind="loss", label="loss of effectiveness"):
    """The actuator delivers ``(1 - loss) u`` for ``start <= t < stop``.

    The plant receives the fault ``fa = -loss * u / c``, where ``c`` is the ratio of the
    fault's column of Bf to the input's column of B (1 when ``Bf = B``). ``fault`` names an
    actuator fault of the plant; ``input`` names the input it degrades (default: the input
    whose column of B is parallel to the fault's column of Bf).

    A loss scales the input the actuator delivers: ``u_operating + u`` for a plant written in
    deviations from an operating point (``b.operating_point(u=...)``), else ``u`` itself (which
    holds the reference input ``u_ref``). Without an operating point and with a zero reference on
    that input the loss would scale a signal that is zero at rest: it is refused, with what to do.
    """

    fault: str
    loss: float
    start: float
    stop: float
    input: str | None = None

    def validate(self) -> None:
        if not (0.0 <= float(self.loss) <= 1.0):
            raise ParameterError(f"loss of effectiveness must lie in [0, 1]; got {self.loss!r}")

    def check_scale(self, fault_scale: float) -> None:
        if self.loss * fault_scale > 1.0:
            raise ParameterError(
                f"fault_scale = {fault_scale:g} makes the {100 * self.loss:g} % loss of effectiveness of "
                f"{self.fault!r} ({self.start:g} to {self.stop:g}) a loss of {100 * self.loss * fault_scale:g} %; "
                f"a loss is at most 100 %: use fault_scale <= {1.0 / self.loss:g}"
            )

    def rows(self, site: FaultSite) -> FaultRows:
        if site.kind != "actuator":
            raise ParameterError(
                f"loss of effectiveness needs an actuator fault; {self.fault!r} is a {site.kind} fault"
            )
        B, names = site.B, list(site.input_names)
        col = site.Bf[:, site.index]
        if self.input is not None:
            if self.input not in names:
                raise ParameterError(f"loss of effectiveness: input {self.input!r} is not one of {names}")
            i = names.index(self.input)
        else:
            i = int(np.argmax([abs(np.dot(B[:, q], col)) / (np.linalg.norm(B[:, q]) + 1e-300)
                               for q in range(B.shape[1])]))  # fmt: skip
        bq = B[:, i]
        c = float(np.dot(bq, col) / np.dot(col, col)) if np.any(col) else 0.0
        if c == 0.0 or np.linalg.norm(bq - c * col) > 1e-9 * (np.linalg.norm(bq) + 1e-300):
            raise ParameterError(
                f"loss of effectiveness: the column of Bf for {self.fault!r} is not parallel to the column of B "
                f"for input {names[i]!r}, so the fault cannot represent a loss on that input"
            )
        if site.u_operating is None and site.u_ref is not None and float(np.ravel(site.u_ref)[i]) == 0.0:
            raise ParameterError(
                f"scenario {site.scenario!r}: a loss of effectiveness of {self.fault!r} scales input "
                f"{names[i]!r}, which is zero at rest here (no reference input on it and no operating point "
                "declared), so the loss would do next to nothing. If the equations are written in deviations from "
                f"an operating point, declare it with b.operating_point(u=[...]) so that the loss scales the input "
                "the actuator delivers; otherwise describe the fault as a Bias (or Drift) of the delivered input"
            )
        on = site.active(self.start, self.stop)
        lu = site.zeros()
        lu[on] = -(self.loss * c)  # B u + Bf fa = B (1 - loss) u  <=>  fa = -loss * c * u
        a = None
        if site.u_operating is not None:  # delivered input u0 + u: fa = -loss * c * (u0 + u)
            a = site.zeros()
            a[on] = -(self.loss * c * float(np.ravel(site.u_operating)[i]))
        return FaultRows(a=a, lu=lu, input_index=i)


class _Additive(FaultShape):
    """An additive fault ``a(t)`` for ``start <= t < stop`` (actuator or sensor), set by one finite
    parameter, the field named by ``_param``: a subclass gives the profile over the window."""

    _param: ClassVar[str]

    def validate(self) -> None:
        v = getattr(self, self._param)
        if not math.isfinite(float(v)):
            raise ParameterError(f"{self.label} {self._param} must be finite; got {v!r}")

    def profile(self, t: np.ndarray):
        """The fault at the window's sample times ``t`` (an array, or one number for all of them)."""
        raise NotImplementedError(f"{type(self).__name__} does not define profile()")

    def rows(self, site: FaultSite) -> FaultRows:
        on = site.active(self.start, self.stop)
        a = site.zeros()
        a[on] = self.profile(site.t[on])
        return FaultRows(a=a)


@dataclass(frozen=True)
class Bias(_Additive, kind="bias"):
    """Additive fault of constant ``value`` for ``start <= t < stop`` (actuator or sensor)."""

    _param = "value"
    fault: str
    value: float
    start: float
    stop: float

    def profile(self, t: np.ndarray) -> float:
        return self.value


@dataclass(frozen=True)
class Drift(_Additive, kind="drift"):
    """Slowly drifting fault ``f = rate * (t - start)`` for ``start <= t < stop``."""

    _param = "rate"
    fault: str
    rate: float
    start: float
    stop: float

    def profile(self, t: np.ndarray) -> np.ndarray:
        return self.rate * (t - self.start)


@dataclass(frozen=True)
class Stuck(FaultShape, kind="stuck", label="stuck sensor"):
    """A sensor stuck for ``start <= t < stop``.

    "Stuck" means: the sensor's output freezes at the value it read at the first sample
    ``t0`` of the window (``t0`` = first sample time ``>= start``); while stuck the plant
    carries the sensor fault ``fs(t) = y_k(t0) - (C x)_k(t)`` (divided by ``Df[k, j]`` when
    that is not 1), so ``fs(t0) = 0`` and ``y_k(t) = y_k(t0)`` throughout the window.
    ``fault`` names a sensor fault of the plant; the output is the row of Df it enters.
    """

    fault: str
    start: float
    stop: float

    def rows(self, site: FaultSite) -> FaultRows:
        if site.kind != "sensor":
            raise ParameterError(
                f"a stuck sensor needs a sensor fault; {self.fault!r} is a {site.kind} fault"
            )
        out = np.flatnonzero(site.Df[:, site.index])
        if len(out) != 1:
            raise ParameterError(
                f"stuck sensor {self.fault!r} must enter exactly one output (one non-zero in its Df column)"
            )
        on = site.active(self.start, self.stop)
        st, la = site.zeros(), site.zeros()
        st[on] = 1.0
        first = np.flatnonzero(on)
        if len(first):
            la[first[0]] = 1.0
        k = int(out[0])
        return FaultRows(st=st, la=la, output_index=k, output_gain=float(site.Df[k, site.index]))
