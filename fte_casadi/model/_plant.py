"""The symbolic stochastic plant: a frozen record and the builder that validates it.

A user writes the nonlinear plant with CasADi ``SX`` symbols handed out by
:class:`PlantBuilder`::

    dx = drift(x, u, d, f, z) dt + diffusion(x, u, f, d2, z) dw,   y = C x + Df f

``z`` are *scheduling symbols*: premise variables of the sector-nonlinearity method
(``b.premise("mu", sin(th)/th)``) or the memberships of local linearisation
(``b.operating_points(...)``). The true nonlinear plant is obtained by substituting
their expressions in ``x``; the T-S derivation uses the symbols themselves. Every check
is done once, in :meth:`PlantBuilder.build`; the returned :class:`Plant` is frozen.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import PlantError
from ._record import Plant as Plant
from ._record import _names, _units, label
from ._validate import validate

__all__ = ["Plant", "PlantBuilder"]


class PlantBuilder:
    """Collects a plant's symbols and equations, then validates them once in :meth:`build`.

    Examples
    --------
    >>> import casadi as ca
    >>> b = PlantBuilder("pendulum")
    >>> th, om = b.states("theta", "omega")
    >>> (u,) = b.inputs("u")
    >>> (d,) = b.unknown_inputs("d")
    >>> (fa,) = b.faults("fa", kind="actuator")
    >>> mu = b.premise("mu", ca.if_else(ca.fabs(th) < 1e-6, 1 - th**2 / 6, ca.sin(th) / th))
    >>> b.drift([om + 0.1 * d, -9.8 * mu * th - 0.5 * om + u + fa])
    >>> b.diffusion([0.01 * om, 0.0])
    >>> b.outputs([th])
    >>> b.region(theta=(-3.14, 3.14))
    >>> b.reference(u=[0.0])
    >>> b.initial_state([0.1, 0.0])
    >>> plant = b.build()
    >>> plant.n, plant.m, plant.p
    (2, 1, 1)
    """

    def __init__(self, name: str):
        if not isinstance(name, str) or not name.strip():
            raise PlantError("plant name must be a non-empty string, e.g. PlantBuilder('manipulator')")
        self._name = label("plant name", name)
        self._x: list[ca.SX] = []
        self._xn: tuple[str, ...] = ()
        self._xu: tuple[str, ...] = ()
        self._u: list[ca.SX] = []
        self._un: tuple[str, ...] = ()
        self._d: list[ca.SX] = []
        self._dn: tuple[str, ...] = ()
        self._d2: list[ca.SX] = []
        self._d2n: tuple[str, ...] = ()
        self._f: list[ca.SX] = []
        self._fn: list[str] = []
        self._fk: list[str] = []
        self._z: list[ca.SX] = []
        self._zn: list[str] = []
        self._ze: list[ca.SX] = []
        self._zt: list[str] = []
        self._drift = None
        self._diff = None
        self._y = None
        self._yn: tuple[str, ...] | None = None
        self._yu: tuple[str, ...] | None = None
        self._region: dict[str, tuple[float, float]] = {}
        self._uref = None
        self._uop = None
        self._xref = None
        self._x0 = None
        self._ops = None
        self._opu = None
        self._sched = None
        self._params: dict[str, float] = {}
        self._time_unit = "s"
        self._design: dict[str, float] = {}
        self._ulim: dict[str, object] = {}

    # -- symbols -------------------------------------------------------------------------
    def _new(self, kind: str, names) -> tuple[list[ca.SX], tuple[str, ...]]:
        names = _names(kind, names)
        taken = set(self._xn) | set(self._un) | set(self._dn) | set(self._fn) | set(self._zn) | set(self._d2n)
        for nm in names:
            if nm in taken:
                raise PlantError(f"{kind} name {nm!r} is already used by another symbol of this plant")
        if len(set(names)) != len(names):
            raise PlantError(f"{kind} names must be distinct; got {names}")
        return [ca.SX.sym(nm) for nm in names], names

    def states(self, *names: str, units=None) -> tuple[ca.SX, ...]:
        """Declare the states; returns their symbols in order."""
        syms, names = self._new("state", names)
        self._x, self._xn, self._xu = syms, names, _units("state", units, len(names))
        return tuple(syms)

    def inputs(self, *names: str) -> tuple[ca.SX, ...]:
        syms, names = self._new("input", names)
        self._u, self._un = syms, names
        return tuple(syms)

    def unknown_inputs(self, *names: str) -> tuple[ca.SX, ...]:
        """Unknown inputs ``d`` of the drift (decoupled by the observer gain H)."""
        syms, names = self._new("unknown input", names)
        self._d, self._dn = syms, names
        return tuple(syms)

    def diffusion_unknown_inputs(self, *names: str) -> tuple[ca.SX, ...]:
        """Unknown inputs ``d2`` of the diffusion (Section 5 of the paper)."""
        syms, names = self._new("diffusion unknown input", names)
        self._d2, self._d2n = syms, names
        return tuple(syms)

    def faults(self, *names: str, kind: str = "actuator") -> tuple[ca.SX, ...]:
        """Declare faults of one kind (``"actuator"`` or ``"sensor"``); may be called twice."""
        if kind not in ("actuator", "sensor"):
            raise PlantError(f"fault kind must be 'actuator' or 'sensor', not {kind!r}")
        syms, names = self._new("fault", names)
        self._f += syms
        self._fn += names
        self._fk += [kind] * len(names)
        return tuple(syms)

    def premise(self, name: str, expr: ca.SX, text: str | None = None) -> ca.SX:
        """A premise variable of the sector-nonlinearity method; returns its symbol.

        Write the drift and diffusion with the returned symbol where the nonlinearity sits
        (``-c * mu * theta`` for ``-c * sin(theta)``): for fixed premise values the plant
        must be linear in ``x, u, d, f``.
        """
        if self._ops is not None:
            raise PlantError(
                "a plant uses either premises (sector nonlinearity) or operating points, not both"
            )
        (sym,), (name,) = self._new("premise", (name,))
        if not isinstance(expr, ca.SX) or expr.numel() != 1:
            raise PlantError(f"premise {name!r} must be a scalar CasADi SX expression of the states")
        self._z.append(sym)
        self._zn.append(name)
        self._ze.append(expr)
        self._zt.append(text if text is not None else str(expr))
        return sym

    def operating_points(self, scheduling: ca.SX, points, inputs=None) -> tuple[ca.SX, ...]:
        """Local linearisation at ``points`` (rows of state values), scheduled on one state.

        Memberships are triangular in the scheduling state, centred on its value at each
        point (which must increase strictly), and saturated outside the first and last
        centre so that they stay a convex sum. ``inputs`` are the inputs at each point;
        by default the input that best holds the point in equilibrium (least squares).
        Returns the membership symbols ``h_1..h_r``: drift or diffusion may use them to
        give rule-wise terms (e.g. the paper's W_i of the three-tank).
        """
        if self._z:
            raise PlantError(
                "a plant uses either premises (sector nonlinearity) or operating points, not both"
            )
        if not self._x:
            raise PlantError("declare the states before the operating points")
        idx = [k for k, s in enumerate(self._x) if ca.is_equal(s, scheduling)]
        if not idx:
            raise PlantError("operating_points: 'scheduling' must be one of the state symbols")
        pts = np.atleast_2d(np.asarray(points, dtype=float))
        if pts.shape[1] != len(self._x):
            raise PlantError(
                f"operating points have {pts.shape[1]} columns; expected {len(self._x)} (one per state)"
            )
        if pts.shape[0] < 2:
            raise PlantError("give at least two operating points")
        if not np.all(np.isfinite(pts)):
            raise PlantError("operating points must be finite numbers")
        v = pts[:, idx[0]]
        if np.any(np.diff(v) <= 0):
            raise PlantError(
                f"the scheduling state must increase strictly over the operating points; got {v.tolist()}"
            )
        self._ops, self._sched = pts, idx[0]
        self._opu = None if inputs is None else np.atleast_2d(np.asarray(inputs, dtype=float))
        syms, names = self._new("membership", [f"rule{k + 1}" for k in range(pts.shape[0])])
        self._z, self._zn = syms, list(names)
        return tuple(syms)

    # -- equations -----------------------------------------------------------------------
    def drift(self, exprs) -> None:
        self._drift = exprs

    def diffusion(self, exprs) -> None:
        """Coefficient of the scalar Brownian increment dw (one entry per state)."""
        self._diff = exprs

    def outputs(self, exprs, names=None, units=None) -> None:
        """Outputs ``y = C x + Df f``; names default to ``y1, y2, ...``."""
        self._y = exprs
        self._yn = None if names is None else _names("output", names)
        self._yu = units

    def region(self, **bounds: tuple[float, float]) -> None:
        """Bounds of operation per state name, e.g. ``region(theta_l=(-6.3, 6.3))``."""
        self._region.update(bounds)

    def reference(self, u=None, x=None) -> None:
        """Reference input ``u`` (added to the feedback), or a reference state ``x``.

        With ``x`` the design computes the input ``u_eq`` that holds the nonlinear plant
        at ``x`` and uses ``u_ref = u_eq - K x`` so that ``u = u_eq + K (xhat - x)``.
        """
        if (u is None) == (x is None):
            raise PlantError("reference: give exactly one of u= (reference input) or x= (reference state)")
        self._uref = None if u is None else np.atleast_1d(np.asarray(u, dtype=float))
        self._xref = None if x is None else np.atleast_1d(np.asarray(x, dtype=float))

    def operating_point(self, u) -> None:
        """The inputs of the operating point the equations are written about (deviation coordinates).

        With ``b.operating_point(u=[3.0, 3.0])`` the input ``u`` of the equations is a deviation and the
        actuator delivers ``3.0 + u``: a :class:`~fte_casadi.sim.LossOfEffectiveness` scales that, as a
        worn pump would. Without it the input of the equations is taken to be the delivered one.
        """
        self._uop = np.atleast_1d(np.asarray(u, dtype=float))

    def input_limits(self, **limits) -> None:
        """Actuator limits per input name, e.g. ``b.input_limits(Q1=(0, 100), Q2=(0, 100))``.

        Either side may be infinite (``-inf``/``inf`` or ``None``). The simulation applies the
        saturated input to the plant and feeds the observer the input actually applied (so a
        saturating actuator does not corrupt the estimates); the generated C saturates the same way.
        """
        self._ulim.update(limits)

    def initial_state(self, x0) -> None:
        self._x0 = np.atleast_1d(np.asarray(x0, dtype=float))

    def parameters(self, **params: float) -> None:
        """Physical parameters, recorded with the plant (documentation and reports)."""
        self._params.update({k: float(v) for k, v in params.items()})

    def time_unit(self, unit: str) -> None:
        self._time_unit = label("time unit", unit)

    def design_defaults(self, **values: float) -> None:
        """Default design parameters: any of gamma, gamma1, sigma, delta, epsilon, and the knobs
        ``fte tune`` finds: alpha (the observer decay rate), kappa (the bound on cond(Pbar)),
        boundary_layer (the sliding term's ``sat(s/phi)`` width) and bound_weight (the fault-error
        bound's weight in step 5's objective)."""
        allowed = {
            "gamma",
            "gamma1",
            "sigma",
            "delta",
            "epsilon",
            "alpha",
            "kappa",
            "boundary_layer",
            "bound_weight",
        }
        for k, v in values.items():
            if k not in allowed:
                raise PlantError(f"design_defaults: unknown parameter {k!r}; allowed are {sorted(allowed)}")
            try:
                fv = float(v)
            except (TypeError, ValueError):
                raise PlantError(f"design_defaults: {k} must be a number; got {v!r}") from None
            if not (np.isfinite(fv) and fv > 0):
                raise PlantError(f"design_defaults: {k} must be a positive finite number; got {v!r}")
            if k == "kappa" and fv <= 1:
                raise PlantError(
                    f"design_defaults: kappa (the bound on cond(Pbar)) must be above 1; got {v!r}"
                )
            self._design[k] = fv

    # -- validation ----------------------------------------------------------------------
    def build(self) -> Plant:
        """Check everything once and return the frozen :class:`Plant`."""
        return validate(self)
