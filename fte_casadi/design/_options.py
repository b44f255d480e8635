"""The settings of a design: what the user gave (:class:`DesignOptions`) and what they resolve to (:class:`Resolved`).

A design is asked for with one frozen record; a retry (another solver, another sigma) is the same record
changed with :func:`dataclasses.replace`. The record holds what was *given*: a parameter left ``None`` stays
``None`` in every retry, and :func:`resolve` fills it, for each attempt, from the plant's design defaults and
then from :data:`GENERIC_DEFAULTS`, noting where each value came from (:attr:`Resolved.alpha_source`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import ParameterError
from ..ts import TSModel

__all__ = ["DesignOptions", "resolve"]

GENERIC_DEFAULTS = {"gamma": 1.0, "gamma1": 0.5, "sigma": 1.0, "delta": 1e-4, "epsilon": 1e-4}
VARIANTS = ("paper", "conditioned")
#: the design defaults a plant may record from `fte tune` (beside the LMI parameters)
TUNED_KNOBS = ("alpha", "beta", "kappa", "boundary_layer", "bound_weight")
SOLVERS = ("CLARABEL", "SCS")
#: the LMI parameters of Theorems 3 and 5, resolved together by :func:`_params`
LMI_PARAMETERS = ("gamma", "gamma1", "sigma", "delta", "epsilon")


def _number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


@dataclass(frozen=True)
class DesignOptions:
    """What the user asks of :func:`~fte_casadi.design.design`; every number ``None`` is resolved per attempt.

    Checked once, on construction (:class:`~fte_casadi.errors.ParameterError` naming the field); the values
    that need the plant (``initial_state``'s length, ``d_bound``'s count, ``gamma1 < gamma`` after the
    defaults) are checked by :func:`resolve`. Change one with :meth:`replace`.

    Parameters
    ----------
    variant : ``"conditioned"`` (default: the printed LMIs posed with a unique, well-scaled answer) or
        ``"paper"`` (as printed).
    solver : ``"CLARABEL"`` (default) or ``"SCS"`` (any case).
    gamma, gamma1, sigma, delta, epsilon : the LMI parameters of Theorem 3 (positive; default: the plant's,
        else :data:`GENERIC_DEFAULTS`, gamma, gamma1 and sigma taken in the outputs' own size, gamma and
        gamma1 also in the unknown inputs' own size).
    gamma2 : the d2 attenuation of Theorem 5 (default gamma).
    alpha : the observer decay rate of the conditioned variant (>= 0; default: the plant's, else a fraction
        of the largest feasible one; either is lowered so that ``ts_max >= 2 sample_time``).
    beta : the closed loop's decay rate asked of (45) in the conditioned variant (>= 0; default: twice the open
        loop's slowest decay rate, or as fast as it diverges, lowered to a fraction of the largest (45) allows;
        :func:`~fte_casadi.design.core._decay.loop_decay_target`).
    sample_time : the step the design is certified for (positive; default none).
    settle_window : the shortest fault window the observer must settle in, three time constants (positive;
        default none: no requirement; ``fte design`` takes the plant's scenario's); kappa is searched for it.
    kappa : the bound on cond(X') and cond(Pbar) (above 1).
    bound_weight : the fault-error bound's weight in step 5's objective (>= 0; 0 is off).
    initial_state : the nominal x(0) (default: the plant's).
    allow_uncertified : return a design whose certificate fails instead of raising.
    accept_assumptions : the names of failed assumptions to accept (or True for all).
    plant_spec : how the plant was named (recorded in the document).
    diagnose : name feasible bounds (and search the generic parameters) when the design fails.
    remark5 : apply Remark 5's fallback where H cannot decouple the unknown inputs.
    d_bound : a bound on ``|d|`` for Remark 5's sliding gain (one number, or one per unknown input).

    Examples
    --------
    >>> import dataclasses
    >>> o = DesignOptions(sigma=0.2, sample_time=1e-3)
    >>> dataclasses.replace(o, solver="scs").solver, o.alpha is None
    ('SCS', True)
    """

    variant: str = "conditioned"
    solver: str = "CLARABEL"
    gamma: float | None = None
    gamma1: float | None = None
    sigma: float | None = None
    delta: float | None = None
    epsilon: float | None = None
    gamma2: float | None = None
    alpha: float | None = None
    beta: float | None = None
    sample_time: float | None = None
    settle_window: float | None = None
    kappa: float | None = None
    bound_weight: float | None = None
    initial_state: Any = None
    allow_uncertified: bool = False
    accept_assumptions: Any = ()
    plant_spec: str | None = None
    diagnose: bool = True
    remark5: bool = True
    d_bound: Any = field(default=None)

    def __post_init__(self):
        if self.variant not in VARIANTS:
            raise ParameterError(f"variant must be one of {VARIANTS}; got {self.variant!r}")
        solver = str(self.solver).upper()
        if solver not in SOLVERS:
            raise ParameterError(f"solver must be one of {SOLVERS}; got {self.solver!r}")
        object.__setattr__(self, "solver", solver)
        for k in (*LMI_PARAMETERS, "gamma2"):
            v = getattr(self, k)
            if v is not None and not (_number(v) and v > 0):
                raise ParameterError(f"{k} must be a positive finite number; got {v!r}")
        if self.kappa is not None and not (_number(self.kappa) and self.kappa > 1):
            raise ParameterError(
                f"kappa (the bound on cond(Pbar)) must be a finite number above 1; got {self.kappa!r}"
            )
        if self.bound_weight is not None and not (_number(self.bound_weight) and self.bound_weight >= 0):
            raise ParameterError(
                f"bound_weight (the fault-error bound's weight in step 5's objective) must be a finite number >= 0; "
                f"got {self.bound_weight!r}"
            )
        if self.alpha is not None and not (_number(self.alpha) and self.alpha >= 0):
            raise ParameterError(f"alpha must be a non-negative finite number; got {self.alpha!r}")
        if self.beta is not None and not (_number(self.beta) and self.beta >= 0):
            raise ParameterError(
                f"beta (the closed loop's decay rate) must be a non-negative finite number; got {self.beta!r}"
            )
        if self.sample_time is not None and not (_number(self.sample_time) and self.sample_time > 0):
            raise ParameterError(f"sample_time must be a positive finite number; got {self.sample_time!r}")
        if self.settle_window is not None and not (_number(self.settle_window) and self.settle_window >= 0):
            raise ParameterError(
                f"settle_window (the fault window the observer must settle in) must be a finite number >= 0 (0: no "
                f"requirement); got {self.settle_window!r}"
            )

    def replace(self, **changes) -> DesignOptions:
        """This record with ``changes`` (:func:`dataclasses.replace`)."""
        return dataclasses.replace(self, **changes)

    def flags(self) -> str:
        """The ``fte design`` options this record was given that advice must keep (e.g. ``" --kappa 1e+06"``): the
        LMI parameters, the rates, kappa and the bound weight, the variant and solver where not the defaults. What
        ``fte design`` fills from the plant's scenario (the sample time, the window, the start) is left out: it fills
        it again."""
        out = []
        if self.variant != "conditioned":
            out.append(f"--variant {self.variant}")
        if self.solver != "CLARABEL":
            out.append(f"--solver {self.solver}")
        for k in (*LMI_PARAMETERS, "alpha", "beta", "kappa", "bound_weight"):
            v = getattr(self, k)
            if v is not None:
                out.append(f"--{k.replace('_', '-')} {v:g}")
        return "".join(" " + f for f in out)


@dataclass(frozen=True)
class Resolved:
    """What one attempt designs with: the options' ``None`` filled from the plant's defaults and the generic ones.

    ``params`` is the design document's ``params`` (the LMI parameters, then ``boundary_layer``, ``gamma2``,
    ``kappa``, ``bound_weight`` where set). ``alpha`` is the decay rate asked for and ``alpha_source`` where it
    came from: ``"user"`` (refused where infeasible), ``"plant"`` (the plant's recorded default: lowered where
    infeasible or where the sample time needs it, like the rate found by default) or ``None`` (found by
    default). ``generic``: the parameters among gamma and sigma that came from the generic defaults, which the
    parameter search may change. ``notes``: the status lines of the resolution. ``beta``: the closed loop's decay
    rate asked (the user's or the plant's; None: the default of step 3)."""

    params: dict
    alpha: float | None
    alpha_source: str | None
    generic: frozenset
    x0: np.ndarray
    notes: tuple
    beta: float | None = None


def generic_sizes(ts: TSModel) -> tuple[float, float]:
    """``(sy, sd)``: the outputs' own size (the power of two nearest the largest row norm of C,
    :func:`~fte_casadi.design._augment.output_size`) and the unknown inputs' own size in units of it
    (:func:`~fte_casadi.design._augment.unknown_input_size`)."""
    from ._augment import augment, output_size, unknown_input_size

    return output_size(ts.C), unknown_input_size(augment(ts.local_models, ts.C, ts.Df))


def gamma_size(ts: TSModel) -> float:
    """The size the generic gamma and gamma1 are taken in, ``sy sd``; the parameter search rounds its gammas in
    this unit (:func:`round_gamma`), so that its choice does not depend on the units of y and d either."""
    sy, sd = generic_sizes(ts)
    return sy * sd


def round_gamma(v: float, size: float) -> float:
    """``v`` rounded up to two significant digits in units of ``size`` (:func:`gamma_size`)."""
    from .._rounding import nice_ceil

    return nice_ceil(v / size) * size


def _generic_scale(ts: TSModel, given: dict) -> tuple[tuple[float, float], dict]:
    """Factors for the generic gamma, gamma1 and sigma: they are taken in the outputs' own size ``sy`` and
    gamma, gamma1 also in the unknown inputs' own size ``sd`` (:func:`generic_sizes`).

    gamma bounds the gain from the unknown input to the outputs, so a number for it carries the units of
    both. Outputs: the generic 1 asks a plant measured in mm for 1000 times the attenuation it asks of the
    same plant measured in m. (45) with outputs ``y / sy`` at ``(sigma, gamma, gamma1)`` is (45) with y at
    ``(sigma / sy^2, gamma sy, gamma1 sy)`` (:func:`~fte_casadi.design._augment.units_params`), and (46),
    (55), (64) and step 5's objective follow (:func:`~fte_casadi.design.core._step5._step5_problem`):
    Pbar scaled by ``sy^2``, the gains L_i1 by ``1 / sy``, the same K, decay rate and largest sample time
    (``tests/test_slow_plant.py``). Unknown inputs: with ``d' = c d`` (``Bd' = Bd / c``) the d block
    ``[.., Bd; Bd^T, (gamma1^2 - gamma^2) I]`` of (45) is congruent, by ``diag(I, I, I, c I)``, to the one at
    ``(gamma / c, gamma1 / c)``, and step 3's margin on it with it; d enters (46) only in a decoupled
    ``-gamma1^2 I`` block, and (55), (64) and H not at all (H and T depend on the range of C Bd). So at
    ``gamma = 1 sy sd``, ``gamma1 = 0.5 sy sd`` a plant gets the same design whatever unit its outputs and
    its unknown inputs are in (``tests/test_d_units.py``). gamma1, when not given, is in that size even
    where gamma was given (then lowered below it where needed). Values the user or the plant's defaults gave
    are kept."""
    sy, sd = generic_sizes(ts)
    defaults = getattr(ts.plant, "design_defaults", {}) or {}
    generic = {k for k in ("gamma", "gamma1", "sigma") if given.get(k) is None and k not in defaults}
    scale = {"gamma": sy * sd, "gamma1": sy * sd, "sigma": sy**-2}
    return (sy, sd), {k: (scale[k] if k in generic else 1.0) for k in given}


def _params(ts: TSModel, given: dict, status: list) -> dict:
    """The LMI parameters ``given`` (None: not given) completed from the plant's defaults, then the generic
    ones; appends to ``status`` what was scaled or lowered."""
    plant_defaults = dict(getattr(ts.plant, "design_defaults", {}) or {})
    out = {}
    for k, v in given.items():
        if v is not None:
            if not (_number(v) and v > 0):
                raise ParameterError(f"{k} must be a positive finite number; got {v!r}")
            out[k] = float(v)
    (sy, sd), factor = _generic_scale(ts, given)
    for k in given:
        if k not in out:
            out[k] = float(plant_defaults.get(k, GENERIC_DEFAULTS[k] * factor[k]))
    scaled = sorted(k for k, f in factor.items() if f != 1.0)
    if scaled:
        status.append(
            f"generic values in the outputs' own size (C's largest row norm, as a power of two, is {sy:g}) and, "
            f"for gamma and gamma1, the unknown inputs' own size ({sd:.4g}: how far the largest moves the outputs "
            "in the plant's time): "
            + ", ".join(f"{k} = {out[k]:g}" for k in scaled)
            + ", so that what they ask does not depend on the units of y and d"
        )
    if given["gamma1"] is None and out["gamma1"] >= out["gamma"]:
        ratio = plant_defaults.get("gamma1", GENERIC_DEFAULTS["gamma1"]) / plant_defaults.get(
            "gamma", GENERIC_DEFAULTS["gamma"]
        )
        out["gamma1"] = min(ratio, 0.5) * out["gamma"]
        status.append(
            f"gamma1 lowered to {out['gamma1']:g} (the default {ratio:g} * gamma) to keep gamma1 < gamma"
        )
    if (
        given["gamma1"] is not None
        and "gamma" not in plant_defaults
        and given["gamma"] is None
        and out["gamma1"] >= out["gamma"]
    ):
        ratio = GENERIC_DEFAULTS["gamma1"] / GENERIC_DEFAULTS["gamma"]
        out["gamma"] = (
            out["gamma1"] / ratio
        )  # a generic gamma follows a given gamma1, as gamma1 follows gamma
        status.append(
            f"gamma raised to {out['gamma']:g} (the given gamma1 / {ratio:g}) to keep gamma1 < gamma"
        )
    if out["gamma1"] >= out["gamma"]:
        raise ParameterError(
            f"gamma1 must be smaller than gamma (Theorem 2); got gamma1 = {out['gamma1']:g} >= gamma = {out['gamma']:g}"
        )
    return out


def default_gamma1(ts: TSModel, options: DesignOptions) -> float:
    """The gamma1 the defaults give before it is lowered below gamma (the plant's, else the generic one in the
    outputs' and unknown inputs' own size)."""
    given = {k: getattr(options, k) for k in ("gamma", "gamma1", "sigma")}
    return float(
        (getattr(ts.plant, "design_defaults", {}) or {}).get(
            "gamma1", GENERIC_DEFAULTS["gamma1"] * _generic_scale(ts, given)[1]["gamma1"]
        )
    )


def _initial_state(plant, x0) -> np.ndarray:
    """The nominal initial state: ``x0`` if given (checked against the plant's states), else the plant's."""
    if x0 is None:
        return np.array(plant.x0, dtype=float).ravel()
    a = np.asarray(x0, dtype=float).ravel()
    if a.shape != (plant.n,) or not np.all(np.isfinite(a)):
        raise ParameterError(
            f"initial_state must hold {plant.n} finite numbers (one per state of {plant.name!r}); got {list(a)}"
        )
    return a


def resolve(ts: TSModel, options: DesignOptions) -> Resolved:
    """The settings one attempt designs ``ts`` with: ``options`` completed from the plant's design defaults
    (``fte tune``'s knobs among them) and :data:`GENERIC_DEFAULTS`. ``options`` itself is left as given, so a
    retry resolves the plant's defaults again, as defaults."""
    o = options
    status: list[str] = []
    params = _params(ts, {k: getattr(o, k) for k in LMI_PARAMETERS}, status)
    plant_defaults = getattr(ts.plant, "design_defaults", {}) or {}
    tuned = {k: plant_defaults[k] for k in TUNED_KNOBS if k in plant_defaults}
    alpha = o.alpha if o.alpha is not None else tuned.get("alpha")
    alpha_source = "user" if o.alpha is not None else ("plant" if alpha is not None else None)
    kappa = tuned.get("kappa") if o.kappa is None else o.kappa
    bound_weight = tuned.get("bound_weight") if o.bound_weight is None else o.bound_weight
    if "boundary_layer" in tuned:
        params["boundary_layer"] = float(tuned["boundary_layer"])
    if tuned:
        status.append(
            "from the plant's design defaults: " + ", ".join(f"{k} = {v:g}" for k, v in tuned.items())
        )
    generic = frozenset(k for k in ("gamma", "sigma") if getattr(o, k) is None and k not in plant_defaults)
    if o.gamma2 is not None:
        params["gamma2"] = float(o.gamma2)
    if kappa is not None:
        params["kappa"] = float(kappa)
    if bound_weight is not None and bound_weight > 0:
        params["bound_weight"] = float(bound_weight)
    if any(lm.has_diffusion_extension for lm in ts.local_models):  # Theorem 5: d2 attenuated as gamma
        params.setdefault("gamma2", params["gamma"])
    x0 = _initial_state(ts.plant, o.initial_state)
    beta = o.beta if o.beta is not None else tuned.get("beta")
    return Resolved(params, alpha, alpha_source, generic, x0, tuple(status), beta)
