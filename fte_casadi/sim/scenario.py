"""Scenarios: fault profiles, unknown inputs, initial-state noise, horizon and step.

Everything is a frozen dataclass, validated once when it is made. A scenario is resolved
against a plant (fault names -> indices, the input an actuator fault acts on, the output a
sensor fault acts on) by :func:`fault_schedule`, which turns the profiles into per-sample
coefficients the compiled closed-loop sample consumes::

    f_j(t_k) = a_j(t_k) + lu_j(t_k) * u_k[iu_j] + st_j(t_k) * (m_j - (C x_k)[k_j]) / Df[k_j, j]

``a`` carries biases and drifts, ``lu`` loss of effectiveness, ``st`` a stuck sensor, whose
remembered reading ``m_j`` is latched (``la_j = 1``) at the first sample of its window.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field

import numpy as np

from ..errors import ParameterError

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


def _positive(name: str, value: float, *, allow_zero: bool = False) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ParameterError(f"{name} must be a number; got {value!r}") from None
    if not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        kind = "non-negative" if allow_zero else "positive"
        raise ParameterError(f"{name} must be a {kind} finite number; got {value!r}")
    return v


def _window(kind: str, start: float, stop: float) -> None:
    for nm, v in (("start", start), ("stop", stop)):
        if not (isinstance(v, (int, float)) and math.isfinite(v)):
            raise ParameterError(f"{kind}: {nm} must be a finite number; got {v!r}")
    if not start < stop:
        raise ParameterError(f"{kind}: the window must have start < stop; got [{start}, {stop})")


@dataclass(frozen=True)
class LossOfEffectiveness:
    """The actuator delivers ``(1 - loss) u`` for ``start <= t < stop``.

    The plant receives the fault ``fa = -loss * u / c``, where ``c`` is the ratio of the
    fault's column of Bf to the input's column of B (1 when ``Bf = B``). ``fault`` names an
    actuator fault of the plant; ``input`` names the input it degrades (default: the input
    whose column of B is parallel to the fault's column of Bf).
    """

    fault: str
    loss: float
    start: float
    stop: float
    input: str | None = None
    kind: str = field(default="loss", init=False)

    def __post_init__(self):
        _window("loss of effectiveness", self.start, self.stop)
        if not (0.0 <= float(self.loss) <= 1.0):
            raise ParameterError(f"loss of effectiveness must lie in [0, 1]; got {self.loss!r}")


@dataclass(frozen=True)
class Bias:
    """Additive fault of constant ``value`` for ``start <= t < stop`` (actuator or sensor)."""

    fault: str
    value: float
    start: float
    stop: float
    kind: str = field(default="bias", init=False)

    def __post_init__(self):
        _window("bias", self.start, self.stop)
        if not math.isfinite(float(self.value)):
            raise ParameterError(f"bias value must be finite; got {self.value!r}")


@dataclass(frozen=True)
class Drift:
    """Slowly drifting fault ``f = rate * (t - start)`` for ``start <= t < stop``."""

    fault: str
    rate: float
    start: float
    stop: float
    kind: str = field(default="drift", init=False)

    def __post_init__(self):
        _window("drift", self.start, self.stop)
        if not math.isfinite(float(self.rate)):
            raise ParameterError(f"drift rate must be finite; got {self.rate!r}")


@dataclass(frozen=True)
class Stuck:
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
    kind: str = field(default="stuck", init=False)

    def __post_init__(self):
        _window("stuck sensor", self.start, self.stop)


@dataclass(frozen=True)
class UniformNoise:
    """Unknown input drawn afresh each simulation step, uniform in ``[-amplitude, amplitude]``
    independently per entry of d (the paper's "d uniform in [-0.1, 0.1]")."""

    amplitude: float
    kind: str = field(default="uniform", init=False)

    def __post_init__(self):
        _positive("unknown-input amplitude", self.amplitude, allow_zero=True)


@dataclass(frozen=True)
class Sinusoid:
    """Deterministic unknown input ``amplitude * sin(2 pi frequency t + phase)`` on every entry of d."""

    amplitude: float
    frequency: float
    phase: float = 0.0
    kind: str = field(default="sinusoid", init=False)

    def __post_init__(self):
        _positive("sinusoid amplitude", self.amplitude, allow_zero=True)
        _positive("sinusoid frequency", self.frequency, allow_zero=True)


_FAULTS = {"loss": LossOfEffectiveness, "bias": Bias, "drift": Drift, "stuck": Stuck}
_INPUTS = {"uniform": UniformNoise, "sinusoid": Sinusoid}


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
        Fault profiles (:class:`LossOfEffectiveness`, :class:`Bias`, :class:`Drift`, :class:`Stuck`).
    unknown_input : UniformNoise | Sinusoid | None
        ``None``: d = 0.
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
    measurement_noise : sequence of float or None
        Standard deviation of white Gaussian noise added to each output at every step, in the output's
        units (one per output; 0 for a noiseless output), reproducible by seed. ``None``: no noise.
    """

    name: str
    T: float
    dt: float
    faults: tuple = ()
    unknown_input: UniformNoise | Sinusoid | None = None
    x0: tuple | None = None
    x0_noise: float = 0.0
    paths: int = 5
    observer_init: str = "nominal"
    divergence_bound: float = 1e6
    measurement_noise: tuple | None = None

    def __post_init__(self):
        _positive("horizon T", self.T)
        _positive("time step dt", self.dt)
        if self.dt > self.T:
            raise ParameterError(f"time step dt = {self.dt} is longer than the horizon T = {self.T}")
        _positive("initial-state noise", self.x0_noise, allow_zero=True)
        _positive("divergence bound", self.divergence_bound)
        if not isinstance(self.paths, int) or self.paths < 1:
            raise ParameterError(f"scenario paths must be a positive integer; got {self.paths!r}")
        if self.observer_init not in ("nominal", "zero"):
            raise ParameterError(f"observer_init must be 'nominal' or 'zero'; got {self.observer_init!r}")
        object.__setattr__(self, "faults", tuple(self.faults))
        for fp in self.faults:
            if not isinstance(fp, tuple(_FAULTS.values())):
                raise ParameterError(
                    f"unknown fault profile {fp!r}; use LossOfEffectiveness, Bias, Drift or Stuck"
                )
        if self.x0 is not None:
            object.__setattr__(self, "x0", tuple(float(v) for v in self.x0))
        if self.measurement_noise is not None:
            try:
                mn = tuple(float(v) for v in self.measurement_noise)
            except (TypeError, ValueError):
                raise ParameterError(
                    f"measurement_noise must be a list of standard deviations, one per output; got {self.measurement_noise!r}"
                ) from None
            for k, v in enumerate(mn):
                _positive(f"measurement_noise[{k}]", v, allow_zero=True)
            object.__setattr__(self, "measurement_noise", mn)

    def until(self, T: float) -> Scenario:
        """The same experiment over the shorter horizon ``T``: the fault windows that start before ``T``, each
        ending at ``T`` at the latest (a window must lie inside [0, T))."""
        from dataclasses import replace

        faults = tuple(replace(fp, stop=min(float(fp.stop), float(T))) for fp in self.faults if fp.start < T)
        return replace(self, T=float(T), faults=faults)

    def windows(self, fault: str) -> list[tuple[float, float]]:
        """The (start, stop) windows of every profile acting on ``fault``."""
        return [(fp.start, fp.stop) for fp in self.faults if fp.fault == fault]

    # -- serialisation (embedded in result files) ---------------------------------------
    def to_dict(self) -> dict:
        d = asdict(self)
        d["faults"] = [asdict(fp) for fp in self.faults]
        d["unknown_input"] = None if self.unknown_input is None else asdict(self.unknown_input)
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, doc: dict) -> Scenario:
        doc = dict(doc)
        faults = []
        for fp in doc.pop("faults", []):
            fp = dict(fp)
            faults.append(_FAULTS[fp.pop("kind")](**fp))
        ui = doc.pop("unknown_input", None)
        if ui is not None:
            ui = dict(ui)
            ui = _INPUTS[ui.pop("kind")](**ui)
        return cls(faults=tuple(faults), unknown_input=ui, **doc)


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


def _active(t: np.ndarray, start: float, stop: float, dt: float) -> np.ndarray:
    eps = 1e-9 * dt
    return (t >= start - eps) & (t < stop - eps)


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

    A loss of effectiveness scales the input the actuator delivers: ``u_operating + u`` for a plant
    written in deviations from an operating point (``b.operating_point(u=...)``), else ``u`` itself
    (which holds the reference input ``u_ref``). Without an operating point and with a zero reference
    on that input the loss would scale a signal that is zero at rest: it is refused, with what to do.
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
        on = _active(t, fp.start, fp.stop, dt)
        if isinstance(fp, LossOfEffectiveness):
            if fault_kinds[j] != "actuator":
                raise ParameterError(
                    f"loss of effectiveness needs an actuator fault; {fp.fault!r} is a {fault_kinds[j]} fault"
                )
            col = Bf[:, j]
            if fp.input is not None:
                if fp.input not in list(input_names):
                    raise ParameterError(
                        f"loss of effectiveness: input {fp.input!r} is not one of {list(input_names)}"
                    )
                i = list(input_names).index(fp.input)
            else:
                i = int(
                    np.argmax(
                        [
                            abs(np.dot(B[:, q], col)) / (np.linalg.norm(B[:, q]) + 1e-300)
                            for q in range(B.shape[1])
                        ]
                    )
                )
            bq = B[:, i]
            c = float(np.dot(bq, col) / np.dot(col, col)) if np.any(col) else 0.0
            if c == 0.0 or np.linalg.norm(bq - c * col) > 1e-9 * (np.linalg.norm(bq) + 1e-300):
                raise ParameterError(
                    f"loss of effectiveness: the column of Bf for {fp.fault!r} is not parallel to the column of B "
                    f"for input {input_names[i]!r}, so the fault cannot represent a loss on that input"
                )
            if iu[j] not in (-1, i):
                raise ParameterError(
                    f"fault {fp.fault!r}: loss-of-effectiveness profiles on different inputs"
                )
            if u_operating is None and u_ref is not None and float(np.ravel(u_ref)[i]) == 0.0:
                raise ParameterError(
                    f"scenario {scenario.name!r}: a loss of effectiveness of {fp.fault!r} scales input "
                    f"{input_names[i]!r}, which is zero at rest here (no reference input on it and no operating point "
                    "declared), so the loss would do next to nothing. If the equations are written in deviations from "
                    f"an operating point, declare it with b.operating_point(u=[...]) so that the loss scales the input "
                    "the actuator delivers; otherwise describe the fault as a Bias (or Drift) of the delivered input"
                )
            iu[j] = i
            lu[on, j] -= fp.loss * c  # B u + Bf fa = B (1 - loss) u  <=>  fa = -loss * c * u
            if u_operating is not None:  # delivered input u0 + u: fa = -loss * c * (u0 + u)
                a[on, j] -= fp.loss * c * float(np.ravel(u_operating)[i])
        elif isinstance(fp, Bias):
            a[on, j] += fp.value
        elif isinstance(fp, Drift):
            a[on, j] += fp.rate * (t[on] - fp.start)
        elif isinstance(fp, Stuck):
            if fault_kinds[j] != "sensor":
                raise ParameterError(
                    f"a stuck sensor needs a sensor fault; {fp.fault!r} is a {fault_kinds[j]} fault"
                )
            rows = np.flatnonzero(Df[:, j])
            if len(rows) != 1:
                raise ParameterError(
                    f"stuck sensor {fp.fault!r} must enter exactly one output (one non-zero in its Df column)"
                )
            ky[j], kg[j] = int(rows[0]), float(Df[rows[0], j])
            st[on, j] = 1.0
            first = np.flatnonzero(on)
            if len(first):
                la[first[0], j] = 1.0
    return FaultSchedule(a, lu, st, la, tuple(iu), tuple(ky), tuple(kg))
