"""Validation of a :class:`PlantBuilder` into a frozen :class:`Plant` (one check per concept)."""

from __future__ import annotations

from typing import TYPE_CHECKING

import casadi as ca
import numpy as np

from .._text import shorten
from ..errors import PlantError
from ._finite import check_finite
from ._record import Plant, _column, _units

if TYPE_CHECKING:
    from ._plant import PlantBuilder

__all__ = ["triangular_memberships"]  # public: docs/api.md


def _vec(syms: list) -> ca.SX:
    return ca.vertcat(*syms) if syms else ca.SX(0, 1)


def _depends(expr: ca.SX, syms: ca.SX) -> bool:
    return syms.numel() > 0 and expr.numel() > 0 and ca.depends_on(expr, syms)


def _free_check(kind: str, expr: ca.SX, allowed: ca.SX, allowed_text: str) -> None:
    free = ca.symvar(expr)
    allowed_set = {s.name() for s in ca.symvar(allowed)} if allowed.numel() else set()
    extra = [s.name() for s in free if s.name() not in allowed_set]
    if extra:
        raise PlantError(
            f"{kind} uses symbol(s) {extra} that are not {allowed_text}; declare them with the builder "
            "(states(), inputs(), unknown_inputs(), faults(), premise()) or replace them by numbers"
        )


def _linearity(
    kind: str,
    rows: tuple[str, ...],
    expr: ca.SX,
    var: ca.SX,
    var_names: list[str],
    auto: bool = False,
    kinds: dict | None = None,
) -> None:
    """``expr`` must be affine in ``var``: its coefficients may depend on what ``var`` leaves out (the
    premises z; with ``auto`` or local linearisation, the states x too). ``auto`` and ``kinds`` (name -> "input",
    "unknown input", "fault") only word the message."""
    if var.numel() == 0:
        return
    jac = ca.jacobian(expr, var)
    for i in range(jac.shape[0]):
        for j in range(jac.shape[1]):
            e = jac[i, j]
            if _depends(e, var):
                bad = [var_names[k] for k in range(var.numel()) if ca.depends_on(e, var[k])]
                if auto:
                    # a product of two signals (an input times an unknown input): not a function of one to invert
                    other = [b for b in bad if b != var_names[j]]
                    fix = (
                        _product_advice(var_names[j], other[0], kinds or {})
                        if other and var_names[j] not in bad
                        else "rewrite that term: e.g. take the nonlinear function of the input (v = sin(u)) as the "
                        "input and invert it in the controller, or model the actuator as a state"
                    )
                    raise PlantError(
                        f"{kind} row {rows[i]!r} is nonlinear in {var_names[j]!r}: its derivative {shorten(e, 120)} "
                        f"depends on {bad}. Inputs, unknown inputs and faults must enter affinely (their coefficients "
                        f"may depend on the states, which gives premises of their own); {fix}"
                    )
                raise PlantError(
                    f"{kind} row {rows[i]!r} is nonlinear in {var_names[j]!r}: its derivative {shorten(e, 120)} "
                    f"depends on {bad}. This term is not covered by any premise: declare a premise "
                    "variable for it (b.premise(name, expr)) and write the equation with its symbol, "
                    "so that for fixed premises the plant is linear in states, inputs, unknown inputs and faults, "
                    "or declare no premise at all: the premises are then found in the plain equations"
                )


def _product_advice(a: str, b: str, kinds: dict) -> str:
    """What to do with a term multiplying the signals ``a`` and ``b`` (each entering affinely on its own)."""
    head = f"that term multiplies {a!r} by {b!r}, two signals the model takes affinely: "
    if "fault" in (kinds.get(a), kinds.get(b)):
        return head + ("write the fault where it enters, added (u + fa: the actuator delivers u + fa), and give its "
                       "shape in the scenario: a loss of effectiveness is LossOfEffectiveness there")  # fmt: skip
    if kinds.get(a) == kinds.get(b) == "input":
        return (
            head + f"take their product as one input (v = {a} * {b}) and recover the pair in the controller"
        )
    return head + (f"take their product as one signal (e.g. an unknown input standing for {a} * {b}, bounded by the "
                   "product of their bounds), or model one of them as a state")  # fmt: skip


def triangular_memberships(v: ca.SX, centres: np.ndarray) -> list[ca.SX]:
    """Triangular memberships on the centres, saturated outside ``[c_1, c_r]`` (a convex sum)."""
    c = [float(t) for t in centres]
    s = ca.fmin(ca.fmax(v, c[0]), c[-1])
    out = []
    for k in range(len(c)):
        up = (s - c[k - 1]) / (c[k] - c[k - 1]) if k > 0 else ca.SX(1.0)
        down = (c[k + 1] - s) / (c[k + 1] - c[k]) if k < len(c) - 1 else ca.SX(1.0)
        out.append(ca.fmax(0.0, ca.fmin(up, down)))
    return out


def validate(b: PlantBuilder) -> Plant:
    """The frozen :class:`Plant` of ``b``, every declaration checked (one check per concept, in this order: what
    must be declared, what each expression may depend on and how, the outputs, the region, the premises, the
    initial and reference states, finite numbers, the input limits and operating points)."""
    (x, u, d, f, d2, z), drift, diff, y = _declared(b)
    n, m = x.numel(), u.numel()
    _check_dependence(b, (x, u, d, f, d2, z), drift, diff, y)
    xn = list(b._xn)
    C, Df, yn, yu = _output_map(b, x, f, y)
    lo, hi = _region(b, xn, n)
    method, ops, sched, z_expr = _premises(b, x, xn, lo, hi)
    x0, uref, xref = _references(b, n, m)
    zn = list(b._zn) if len(b._zn) == z_expr.numel() else [f"z{k + 1}" for k in range(z_expr.numel())]
    check_finite(
        params=b._params, C=C, Df=Df, state_names=xn, output_names=yn, fault_names=list(b._fn),
        x=x, u=u, d=d, f=f, d2=d2, lo=lo, hi=hi, x0=x0, u_nominal=np.zeros(m) if uref is None else uref,
        rows={"premise": (z_expr, zn),  # first: a premise's coefficient shows in every row using it
              "drift row": (ca.substitute(drift, z, z_expr) if z.numel() else drift, xn),
              "diffusion row": (ca.substitute(diff, z, z_expr) if z.numel() else diff, xn)},
    )  # fmt: skip
    ulim = _input_limits(b, m, uref)
    uop = b._uop
    if uop is not None and (uop.shape != (m,) or not np.all(np.isfinite(uop))):
        raise PlantError(
            f"operating_point(u=...) must hold {m} finite numbers (one per input {list(b._un)}); got {uop.tolist()}"
        )
    opu = _operating_inputs(b, (x, u, d, f, z), drift, ops) if method == "linearisation" else None
    return Plant(
        name=b._name, state_names=tuple(xn), state_units=b._xu, input_names=b._un, unknown_input_names=b._dn,
        fault_names=tuple(b._fn), fault_kinds=tuple(b._fk), output_names=tuple(yn), output_units=yu,
        diffusion_input_names=b._d2n, x=x, u=u, d=d, f=f, d2=d2, z=z, z_names=tuple(b._zn), z_exprs=z_expr,
        z_texts=tuple(b._zt) if method == "sector" else tuple(b._zn), drift_z=drift, diffusion_z=diff, C=C, Df=Df,
        region_lo=lo, region_hi=hi, x0=x0, method=method, u_ref=uref, x_ref=xref, operating_points=ops,
        operating_inputs=opu, scheduling_state=sched, params=dict(b._params), time_unit=b._time_unit,
        design_defaults=dict(b._design), input_limits=ulim, u_operating=uop,
    )  # fmt: skip


def _declared(b: PlantBuilder) -> tuple[tuple, ca.SX, ca.SX, ca.SX]:
    """The symbols ``(x, u, d, f, d2, z)``, the drift, diffusion and output columns; refuses a plant without
    states, inputs, faults, drift or outputs."""
    if not b._x:
        raise PlantError("the plant has no states: call b.states('x1', ...) first")
    if not b._u:
        raise PlantError("the plant has no control inputs: call b.inputs('u', ...)")
    if not b._f:
        raise PlantError(
            "the plant has no faults: declare at least one with b.faults(..., kind='actuator'|'sensor')"
        )
    syms = (_vec(b._x), _vec(b._u), _vec(b._d), _vec(b._f), _vec(b._d2), _vec(b._z))
    n = syms[0].numel()
    if b._drift is None:
        raise PlantError("the plant has no drift: call b.drift([...]) with one expression per state")
    drift = _column("drift", b._drift, n)
    diff = _column("diffusion", b._diff if b._diff is not None else [0.0] * n, n)
    if b._y is None:
        raise PlantError("the plant has no outputs: call b.outputs([...])")
    return syms, drift, diff, _column("outputs", b._y, None)


def _check_dependence(b: PlantBuilder, syms: tuple, drift: ca.SX, diff: ca.SX, y: ca.SX) -> None:
    """Refuse an expression of a symbol it may not use, and an input, unknown input or fault (or, for the sector
    method, a state) entering the drift or diffusion other than affinely."""
    x, u, d, f, d2, z = syms
    _free_check(
        "drift", drift, ca.vertcat(x, u, d, f, z), "states, inputs, unknown inputs, faults or premises"
    )
    _free_check(
        "diffusion",
        diff,
        ca.vertcat(x, u, f, d2, z),
        "states, inputs, faults, diffusion unknown inputs or premises",
    )
    _free_check("outputs", y, ca.vertcat(x, f), "states or faults (y = C x + Df f)")
    xn = list(b._xn)
    auto = b._ops is None and not b._z
    if auto:
        # no premise declared: the states may enter nonlinearly (the premises are found at derive
        # time, fte_casadi.ts._auto); inputs, unknown inputs and faults must enter affinely
        v, vn = ca.vertcat(u, d, f), list(b._un) + list(b._dn) + list(b._fn)
        w, wn = ca.vertcat(u, f, d2), list(b._un) + list(b._fn) + list(b._d2n)
    elif b._ops is None:
        # sector nonlinearity: for fixed premises the plant must be linear in everything
        v, vn = ca.vertcat(x, u, d, f), xn + list(b._un) + list(b._dn) + list(b._fn)
        w, wn = ca.vertcat(x, u, f, d2), xn + list(b._un) + list(b._fn) + list(b._d2n)
    else:
        # local linearisation: x and u may enter nonlinearly; d and f must enter affinely
        v, vn = ca.vertcat(d, f), list(b._dn) + list(b._fn)
        w, wn = ca.vertcat(f, d2), list(b._fn) + list(b._d2n)
    kinds = {**{n: "input" for n in b._un}, **{n: "unknown input" for n in (*b._dn, *b._d2n)},
             **{n: "fault" for n in b._fn}}  # fmt: skip
    _linearity("drift", b._xn, drift, v, vn, auto, kinds)
    _linearity("diffusion", b._xn, diff, w, wn, auto, kinds)


def _output_map(b: PlantBuilder, x: ca.SX, f: ca.SX, y: ca.SX) -> tuple[np.ndarray, np.ndarray, tuple, tuple]:
    """``(C, Df, output names, output units)`` of outputs that are exactly ``y = C x + Df f``; every sensor
    fault in some output."""
    n, p = x.numel(), y.shape[0]
    yn = b._yn or tuple(f"y{k + 1}" for k in range(p))
    if len(yn) != p:
        raise PlantError(f"output names: expected {p} entries instead of {len(yn)}")
    yf = ca.Function("y", [x, f], [y, ca.jacobian(y, x), ca.jacobian(y, f)])
    y0, Cs, Dfs = yf(np.zeros(n), np.zeros(f.numel()))
    xf = ca.vertcat(x, f)
    if _depends(ca.jacobian(y, xf), xf):
        bad = [k for k in range(p) if _depends(ca.jacobian(y[k], xf), xf)]
        raise PlantError(
            "outputs must be linear in states and faults (y = C x + Df f); nonlinear: "
            + ", ".join(f"output {k + 1} ({yn[k]} = {y[k]})" for k in bad)
            + "; measure a linear combination, or make the nonlinear quantity a state"
        )
    if np.max(np.abs(np.array(y0))) > 0:
        raise PlantError(
            "outputs must be y = C x + Df f with no constant offset; subtract it from the measurement"
        )
    C, Df = np.array(Cs, dtype=float), np.array(Dfs, dtype=float)
    for k, kind in enumerate(b._fk):
        if kind == "sensor" and not np.any(Df[:, k]):
            raise PlantError(
                f"sensor fault {b._fn[k]!r} does not appear in any output; add it to an output expression"
            )
    yu = b._yu
    if yu is None:
        yu = []
        for k in range(p):
            nz = np.flatnonzero(C[k])
            yu.append(b._xu[nz[0]] if len(nz) == 1 else "")
    return C, Df, yn, _units("output", yu, p)


def _region(b: PlantBuilder, xn: list[str], n: int) -> tuple[np.ndarray, np.ndarray]:
    """The region's bounds per state (NaN where none is given), each a finite pair, lower below upper."""
    lo, hi = np.full(n, np.nan), np.full(n, np.nan)
    for key, bounds in b._region.items():
        if key not in xn:
            raise PlantError(f"region: {key!r} is not a state of this plant; states are {xn}")
        try:
            a, c = (float(bounds[0]), float(bounds[1]))
        except (TypeError, ValueError, IndexError):
            raise PlantError(
                f"region: bounds of {key!r} must be a pair (lower, upper); got {bounds!r}"
            ) from None
        if not (np.isfinite(a) and np.isfinite(c)):
            raise PlantError(f"region: bounds of {key!r} must be finite; got ({a}, {c})")
        if not a < c:
            raise PlantError(f"region: lower bound of {key!r} must be below its upper bound; got ({a}, {c})")
        k = xn.index(key)
        lo[k], hi[k] = a, c
    return lo, hi


def _premises(b: PlantBuilder, x: ca.SX, xn: list[str], lo: np.ndarray, hi: np.ndarray) -> tuple:
    """``(method, operating points, scheduling state, premise column)``: the sector method's declared premises, or
    the linearisation's triangular memberships (its scheduling state bounded by the operating points where the
    region leaves it open: ``lo``, ``hi`` completed in place). A premise of a state without bounds is refused."""
    z_exprs = list(b._ze)
    method = "sector"
    ops = sched = None
    if b._ops is not None:
        method = "linearisation"
        ops, sched = b._ops, b._sched
        z_exprs = triangular_memberships(x[sched], ops[:, sched])
        if np.isnan(lo[sched]):
            lo[sched], hi[sched] = ops[0, sched], ops[-1, sched]
    z_expr = _vec(z_exprs)
    for k, e in enumerate(z_exprs):
        _free_check(f"premise {b._zn[k]!r}", e, x, "states (premises must be functions of the states)")
        for j in range(x.numel()):
            if ca.depends_on(e, x[j]) and np.isnan(lo[j]):
                raise PlantError(
                    f"premise {b._zn[k]!r} depends on state {xn[j]!r}, which has no bounds: its range would be "
                    f"unbounded. Give bounds with b.region({xn[j]}=(lower, upper))"
                )
    return method, ops, sched, z_expr


def _references(b: PlantBuilder, n: int, m: int) -> tuple:
    """``(x0, u_ref, x_ref)``: the initial state (default zeros) and the reference input or state (default: the
    zero input), each of the right size and finite."""
    x0 = np.zeros(n) if b._x0 is None else b._x0
    if x0.shape != (n,) or not np.all(np.isfinite(x0)):
        raise PlantError(f"initial state must hold {n} finite numbers; got {np.asarray(x0).tolist()}")
    uref, xref = b._uref, b._xref
    if uref is None and xref is None:
        uref = np.zeros(m)
    if uref is not None and (uref.shape != (m,) or not np.all(np.isfinite(uref))):
        raise PlantError(f"reference input must hold {m} finite numbers; got {uref.tolist()}")
    if xref is not None and (xref.shape != (n,) or not np.all(np.isfinite(xref))):
        raise PlantError(f"reference state must hold {n} finite numbers; got {xref.tolist()}")
    return x0, uref, xref


def _operating_inputs(b: PlantBuilder, syms: tuple, drift: ca.SX, ops: np.ndarray) -> np.ndarray:
    """The inputs at the linearisation's operating points: the given ones (r x m), else per point the
    least-squares input that makes the fault- and disturbance-free drift zero."""
    x, u, d, f, z = syms
    r, m = ops.shape[0], u.numel()
    if b._opu is not None:
        opu = b._opu
        if opu.shape != (r, m):
            raise PlantError(f"operating-point inputs must be {r} x {m}; got {opu.shape}")
        return opu
    opu = np.zeros((r, m))
    fz = ca.Function(
        "fz", [x, u, z], [ca.substitute(drift, ca.vertcat(d, f), ca.DM.zeros(d.numel() + f.numel()))]
    )
    for k in range(r):
        zk = np.eye(r)[k]
        f0 = np.array(fz(ops[k], np.zeros(m), zk)).ravel()
        Bk = np.column_stack([np.array(fz(ops[k], np.eye(m)[j], zk)).ravel() - f0 for j in range(m)])
        opu[k] = np.linalg.lstsq(Bk, -f0, rcond=None)[0]
    return opu


def _input_limits(b: PlantBuilder, m: int, uref) -> np.ndarray | None:
    """The (m, 2) limits ``[lo, hi]`` per input (-inf/inf where open), or None when none are given."""
    if not b._ulim:
        return None
    names = list(b._un)
    out = np.tile([-np.inf, np.inf], (m, 1))
    for key, pair in b._ulim.items():
        if key not in names:
            raise PlantError(f"input_limits: {key!r} is not an input of this plant; inputs are {names}")
        try:
            lo, hi = pair
            lo = -np.inf if lo is None else float(lo)
            hi = np.inf if hi is None else float(hi)
        except (TypeError, ValueError):
            raise PlantError(
                f"input_limits: the limits of {key!r} must be a pair (lower, upper), None for an open side; got {pair!r}"
            ) from None
        if np.isnan(lo) or np.isnan(hi) or not lo < hi:
            raise PlantError(f"input_limits: {key!r} needs lower < upper; got ({lo}, {hi})")
        out[names.index(key)] = (lo, hi)
    if uref is not None and np.any((uref < out[:, 0]) | (uref > out[:, 1])):
        bad = [f"{names[k]} = {uref[k]:g} not in [{out[k, 0]:g}, {out[k, 1]:g}]" for k in range(m)
               if not out[k, 0] <= uref[k] <= out[k, 1]]  # fmt: skip
        raise PlantError(f"the reference input lies outside the input limits ({'; '.join(bad)}); the loop would "
                         "saturate at rest: move the reference or widen the limits")  # fmt: skip
    return out
