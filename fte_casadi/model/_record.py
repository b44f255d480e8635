"""The frozen :class:`Plant` record and the checks its builder and its validation share.

:class:`~fte_casadi.model._plant.PlantBuilder` collects a plant, :mod:`._validate` checks it and
returns this record; both use the column and name helpers below (so neither imports the other's
module back).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

import casadi as ca
import numpy as np

from .._labels import label_problem
from ..errors import PlantError

__all__ = ["Plant"]


@dataclass(frozen=True)
class Plant:
    """A validated nonlinear stochastic plant (see :class:`PlantBuilder`)."""

    name: str
    state_names: tuple[str, ...]
    state_units: tuple[str, ...]
    input_names: tuple[str, ...]
    unknown_input_names: tuple[str, ...]
    fault_names: tuple[str, ...]
    fault_kinds: tuple[str, ...]
    output_names: tuple[str, ...]
    output_units: tuple[str, ...]
    diffusion_input_names: tuple[str, ...]
    x: ca.SX
    u: ca.SX
    d: ca.SX
    f: ca.SX
    d2: ca.SX
    z: ca.SX
    z_names: tuple[str, ...]
    z_exprs: ca.SX
    z_texts: tuple[str, ...]
    drift_z: ca.SX
    diffusion_z: ca.SX
    C: np.ndarray
    Df: np.ndarray
    region_lo: np.ndarray
    region_hi: np.ndarray
    x0: np.ndarray
    method: str  # "sector" or "linearisation"
    u_ref: np.ndarray | None = None
    x_ref: np.ndarray | None = None
    operating_points: np.ndarray | None = None
    operating_inputs: np.ndarray | None = None
    scheduling_state: int | None = None
    params: Mapping[str, float] = field(default_factory=dict)
    time_unit: str = "s"
    #: default design parameters (gamma, gamma1, sigma, delta, epsilon) for this plant
    design_defaults: Mapping[str, float] = field(default_factory=dict)
    #: actuator limits, (m, 2) rows [lo, hi] with -inf/inf for an open side; None: no limits
    input_limits: np.ndarray | None = None
    #: the operating point's inputs when the plant is written in deviations from it: the actuator
    #: delivers ``u_operating + u`` (a loss of effectiveness scales that); None: u is the delivered input
    u_operating: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.x.numel()

    @property
    def m(self) -> int:
        return self.u.numel()

    @property
    def ld(self) -> int:
        return self.d.numel()

    @property
    def lf(self) -> int:
        return self.f.numel()

    @property
    def p(self) -> int:
        return self.C.shape[0]

    def names(self, scheduling_sources) -> dict:
        """The names a design document keeps (``Design.names``): the plant's states, inputs, outputs, faults and
        units, with ``scheduling_sources`` (what each premise is computed from)."""
        return {
            "states": list(self.state_names),
            "inputs": list(self.input_names),
            "outputs": list(self.output_names),
            "faults": list(self.fault_names),
            "state_units": list(self.state_units),
            "output_units": list(self.output_units),
            "scheduling_sources": scheduling_sources,
        }

    def nonlinear_drift(self) -> ca.SX:
        """Drift with the scheduling symbols replaced by their expressions in x."""
        return ca.substitute(self.drift_z, self.z, self.z_exprs)

    def nonlinear_diffusion(self) -> ca.SX:
        return ca.substitute(self.diffusion_z, self.z, self.z_exprs)

    def drift_function(self) -> ca.Function:
        """``(x, u, d, f) -> dx/dt`` of the nonlinear plant."""
        return ca.Function(
            f"{_cname(self.name)}_drift",
            [self.x, self.u, self.d, self.f],
            [self.nonlinear_drift()],
            ["x", "u", "d", "f"],
            ["xdot"],
        )

    def diffusion_function(self) -> ca.Function:
        """``(x, u, f, d2) -> g``, the coefficient of the scalar Brownian increment."""
        return ca.Function(
            f"{_cname(self.name)}_diffusion",
            [self.x, self.u, self.f, self.d2],
            [self.nonlinear_diffusion()],
            ["x", "u", "f", "d2"],
            ["g"],
        )


def _cname(name: str) -> str:
    """A CasADi Function name from a plant name: ASCII letters and digits (accents dropped: ``pendül`` ->
    ``pendul``), any other character one ``_``, never two in a row, starting with a letter."""
    import re
    import unicodedata

    plain = unicodedata.normalize("NFKD", name).encode("ascii", "ignore").decode()
    out = re.sub(r"_+", "_", "".join(c if c.isalnum() else "_" for c in plain)).strip("_")
    return out if out[:1].isalpha() else "p_" + out


def _names(kind: str, names: Sequence[str]) -> tuple[str, ...]:
    if isinstance(names, str):
        names = (names,)
    names = tuple(names)
    for nm in names:
        if not isinstance(nm, str) or not nm.isidentifier():
            raise PlantError(f"{kind} name {nm!r} is not a valid identifier; use letters, digits and '_'")
        label(f"{kind} name", nm)
    return names


def label(what: str, text, empty: bool = False) -> str:
    """``text`` when it is a plain label (:func:`fte_casadi._labels.label_problem`), else :class:`PlantError`
    naming ``what`` and what is wrong with it."""
    why = label_problem(text, empty=empty)
    if why:
        raise PlantError(
            f"{what} {text!r} {why}: a name or a unit is a plain label of printable characters on one line, "
            "without '/*', '*/', '//', '??', a backslash or a backquote (it is written into C comments and Markdown)"
        )
    return text


def _units(kind: str, units, count: int) -> tuple[str, ...]:
    if units is None:
        return ("",) * count
    if isinstance(units, str):
        units = (units,) * count
    units = tuple(units)
    if len(units) != count:
        raise PlantError(f"{kind} units: expected {count} entries instead of {len(units)}")
    for u in units:
        label(f"{kind} unit", u, empty=True)
    return units


def _column(kind: str, expr, expected: int | None) -> ca.SX:
    if isinstance(expr, ca.SX):
        v = expr
    else:
        try:
            v = ca.vertcat(*[ca.SX(e) if not isinstance(e, ca.SX) else e for e in expr])
        except Exception as exc:  # noqa: BLE001 - CasADi raises plain RuntimeError/TypeError
            raise PlantError(f"{kind} must be a list of CasADi SX expressions ({exc})") from None
    if v.shape[1] != 1 and v.shape[0] == 1:
        v = v.T
    if v.shape[1] != 1:
        raise PlantError(f"{kind} must be a column of expressions; got shape {v.shape}")
    if expected is not None and v.shape[0] != expected:
        raise PlantError(f"{kind} has the wrong number of rows; expected {expected} instead of {v.shape[0]}")
    return v
