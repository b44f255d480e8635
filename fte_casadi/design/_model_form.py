"""Where a failed assumption is the sector model's form, not the plant: an effect of a state the model hides.

A sector model is exact, ``f(x, u) = A(z(x)) x + B(z(x)) u``, but it is written about x = 0. A plant written in
absolute units with a reference far from 0 (a chemostat's substrate S at 0.3 g/L, its dilution rate D at 0.3 per
h) can have the whole effect of a state held in the premises and the input's coefficient: ``mu(S) X`` telescoped
as ``mu(S) * X`` (S in a premise), ``D (Sf - S)`` as ``B(S) D``. Then every ``A_i`` has a zero column for S
although the plant, at its reference, moves with S (``df/dS``: growth and dilution). The rank tests of the
observer see only the ``A_i``: a sensor fault on S becomes indistinguishable from S itself (assumption (2)), and
S's mode an unobservable eigenvalue 0 (assumption (4)), and the refusal's advice (measure S free of the fault)
would not help: S is measured. Written in deviations from the reference (``S - S_ref``, ``D - D_eq``) the
effect the reference input and state had through those coefficients is part of ``A``.

:func:`hidden_effects` finds such states (a column of every ``A_i`` zero where the plant's Jacobian at the
reference is not) and checks the advice: the plant shifted to its reference, derived again, and assumption (2)'s
rank test run on it.
"""

from __future__ import annotations

import dataclasses
import warnings

import casadi as ca
import numpy as np

from ._uio import rank

__all__ = []

#: a column of every A_i this small against the largest A_i is zero (the telescoping puts an exact 0 there)
ZERO_COLUMN = 1e-12
#: the plant's Jacobian column at the reference, against the whole Jacobian, above which the state moves the plant
MOVES = 1e-6


@dataclasses.dataclass(frozen=True)
class Hidden:
    """The states whose effect the model hides, the reference point, and whether (2) holds in deviations."""

    states: tuple[int, ...]
    x_star: np.ndarray
    u_star: np.ndarray
    jacobian: np.ndarray
    #: assumption (2) on the plant written in deviations from (x_star, u_star): ``(rules where it fails, rules)``;
    #: None: not checked (or that derivation failed)
    in_deviations: tuple[int, int] | None

    def render(self, plant) -> str:
        names = [plant.state_names[k] for k in self.states]
        q = ", ".join(f'"{nm}"' for nm in names)
        rates = "; ".join(
            f"df/d{plant.state_names[k]} = [{_numbers(self.jacobian[:, k])}]" for k in self.states[:3]
        )
        column = f"the column of {q} is" if len(names) == 1 else f"the columns of {q} are"
        fixed = self.in_deviations is not None and self.in_deviations[0] == 0
        head = ("the model's form is the cause, not the plant" if fixed else
                "the model's form may be part of the cause")  # fmt: skip
        text = (
            f"{head}: at its reference the plant moves with {q} ({rates}), but {column} zero in every A_i: the sector "
            "model is written about x = 0, and holds that effect in its premises and in the inputs' state-dependent "
            "coefficients (B(x) times the reference input), which the observer's rank tests do not see as motion. "
            f"{_advice(plant, self.x_star, self.u_star)}: the effect is then part of A"
        )
        if self.in_deviations is not None:
            failed, rules = self.in_deviations
            text += (" (checked: the plant so written derives a model for which assumption (2) holds in every rule)"
                     if not failed else f" (checked: so written, assumption (2) still fails in {failed} of its {rules} "
                     "rules, for another reason: the refusal of the plant so written names it)")  # fmt: skip
        return text


def _numbers(values) -> str:
    """The entries, each below 1e-12 of the largest shown as 0 (``mu(S*) - D*`` is 0 to round-off; no "-0")."""
    values = np.asarray(values, dtype=float)
    tiny = 1e-12 * float(np.max(np.abs(values), initial=0.0))
    return ", ".join(f"{(v if abs(v) > tiny else 0.0) + 0.0:.3g}" for v in values)


def _advice(plant, x_star: np.ndarray, u_star: np.ndarray) -> str:
    """ "Write the plant in deviations from its reference (X - 4.846, S + 0.5; the inputs less [0.3], ...)"."""
    shift = ", ".join(
        f"{nm} {'-' if v > 0 else '+'} {abs(v):.4g}" for nm, v in zip(plant.state_names, x_star) if v
    )
    inputs = np.round(u_star, 6).tolist()
    parts = ([shift] if shift else []) + (
        [f"the inputs less {inputs}, declared by b.operating_point(u={inputs})"] if any(inputs) else []
    )
    return "Write the plant in deviations from its reference" + (f" ({'; '.join(parts)})" if parts else "")


def _drift(plant) -> ca.SX:
    """The plant's drift in x and u, with d = f = 0."""
    return plant.drift_function()(plant.x, plant.u, np.zeros(plant.ld), np.zeros(plant.lf))


def holding_input(plant, xr: np.ndarray) -> np.ndarray:
    """The input that comes nearest to holding the plant at ``xr`` (d = f = 0): Gauss-Newton on the drift there (one
    step where the inputs enter affinely, as the builder asks), the ``u_eq`` of
    :func:`~fte_casadi.design._pipeline.u_reference`."""
    u = ca.SX.sym("u", plant.m)
    g = plant.drift_function()(xr, u, np.zeros(plant.ld), np.zeros(plant.lf))
    J = ca.Function("J", [u], [g, ca.jacobian(g, u)])
    ue = np.zeros(plant.m)
    for _ in range(50):
        r, Jm = (np.array(v) for v in J(ue))
        step = np.linalg.lstsq(Jm, -r.ravel(), rcond=None)[0]
        ue = ue + step
        if np.linalg.norm(step) < 1e-12 * (1 + np.linalg.norm(ue)):
            break
    return ue


def _jacobian(plant, x_star: np.ndarray, u_star: np.ndarray) -> np.ndarray:
    """``df/dx`` of the plant at ``(x_star, u_star)``, d = f = 0."""
    fn = ca.Function("J", [plant.x, plant.u], [ca.jacobian(_drift(plant), plant.x)])
    return np.asarray(fn(x_star, u_star), dtype=float)


def _half_widths(plant) -> np.ndarray:
    """Each state's half-width in the region (1 where it has no finite one)."""
    half = (plant.region_hi - plant.region_lo) / 2.0
    return np.where(np.isfinite(half) & (half > 0.0), half, 1.0)


def reference_point(plant) -> tuple[np.ndarray, np.ndarray] | None:
    """``(x*, u*)``: the reference state and the input that holds the plant there (:func:`holding_input`), or x = 0 with the reference input; None where the plant gives neither, where that point lies outside
    the region, or where the plant is not finite there."""
    if plant.x_ref is None and plant.u_ref is None:
        return None
    x_star = np.zeros(plant.n) if plant.x_ref is None else np.asarray(plant.x_ref, dtype=float).ravel()
    lo, hi = np.nan_to_num(plant.region_lo, nan=-np.inf), np.nan_to_num(plant.region_hi, nan=np.inf)
    if np.any(x_star < lo) or np.any(x_star > hi):
        return None  # a reference outside the region: the model claims nothing there
    if plant.x_ref is None:
        return x_star, np.asarray(plant.u_ref, dtype=float).ravel()
    drift = _drift(plant)
    at_rest = ca.Function("fx", [plant.x, plant.u], [drift, ca.jacobian(drift, plant.u)])(
        x_star, np.zeros(plant.m)
    )
    if not all(np.all(np.isfinite(np.asarray(v, dtype=float))) for v in at_rest):
        return None
    return x_star, holding_input(plant, x_star)


def hidden_effects(ts, check: bool = True) -> Hidden | None:
    """The states the sector model's ``A_i`` do not move with although the plant does at its reference (see the
    module docstring), with ``check``: assumption (2) tested on the plant written in deviations; None where there
    are none, or the model is not a sector model of the plain equations."""
    plant = ts.plant
    if ts.kind not in ("sector_auto", "sector") or (point := reference_point(plant)) is None:
        return None
    x_star, u_star = point
    J = _jacobian(plant, x_star, u_star)
    if not np.all(np.isfinite(J)) or not np.any(J):
        return None
    A = [np.asarray(lm.A, dtype=float) for lm in ts.local_models]
    a_size = max(float(np.linalg.norm(a)) for a in A)
    Jw = J * _half_widths(plant)[None, :]  # a state's column in its own units, weighted by its reach
    states = tuple(
        k
        for k in range(plant.n)
        if max(float(np.linalg.norm(a[:, k])) for a in A) <= ZERO_COLUMN * max(a_size, 1e-300)
        and np.linalg.norm(Jw[:, k]) > MOVES * np.linalg.norm(Jw)
    )
    if not states:
        return None
    return Hidden(states, x_star, u_star, J, _in_deviations(ts, x_star, u_star) if check else None)


def _in_deviations(ts, x_star: np.ndarray, u_star: np.ndarray) -> tuple[int, int] | None:
    """Assumption (2)'s rank test on the plant written in deviations from ``(x_star, u_star)`` (its drift only:
    the rank test does not read the diffusion), derived again: ``(rules where it fails, rules)``; None where that
    derivation fails."""
    from ..errors import FteError
    from ..ts import structure

    plant = ts.plant
    drift = ca.substitute(plant.nonlinear_drift(), ca.vertcat(plant.x, plant.u),
                          ca.vertcat(plant.x + ca.DM(x_star), plant.u + ca.DM(u_star)))  # fmt: skip
    shifted = dataclasses.replace(
        plant, drift_z=drift, diffusion_z=ca.SX.zeros(plant.n), z=ca.SX(0, 1), z_names=(), z_exprs=ca.SX(0, 1),
        z_texts=(), region_lo=plant.region_lo - x_star, region_hi=plant.region_hi - x_star, x0=plant.x0 - x_star,
        x_ref=None, u_ref=None, method="sector", operating_points=None, operating_inputs=None,
        scheduling_state=None, u_operating=u_star,
    )  # fmt: skip
    try:
        with (
            warnings.catch_warnings()
        ):  # a warning of many premises is about this trial, not the user's plant
            warnings.simplefilter("ignore")
            dev = structure(shifted)
    except (FteError, ValueError, RuntimeError):
        return None
    p = dev.C.shape[0]
    blocks = [np.block([[lm.A, lm.Bf, lm.Bd], [dev.C, dev.Df, np.zeros((p, lm.Bd.shape[1]))]])
              for lm in dev.local_models]  # fmt: skip
    return sum(rank(M) < M.shape[1] for M in blocks), len(blocks)


#: how far the model's A at the reference is off in a state's rate (:func:`row_shares`), above which it warns
MISSED = 0.2


def row_shares(J: np.ndarray, A: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """Per state i, ``||(J - A)_i w|| / max(||J_i w||, ||A_i w||)`` (0 where both rows are 0): how much of the
    state's rate the model's ``A`` gets wrong, each state's column weighted by ``w`` (its half-width in the region),
    so that the share does not depend on the units the states are written in (a column of a state in mm and its
    half-width in mm scale inversely; a row's own unit cancels in the ratio). A plain norm of ``J - A`` would let
    one large entry hide the rest: a generator's 314 rad/s per pu of speed hides its missing synchronising torque."""
    Jw, Aw = J * weights[None, :], A * weights[None, :]
    den = np.maximum(np.linalg.norm(Jw, axis=1), np.linalg.norm(Aw, axis=1))
    return np.where(den > 0.0, np.linalg.norm(Jw - Aw, axis=1) / np.where(den > 0.0, den, 1.0), 0.0)


def missed_motion(ts) -> tuple[float, str] | None:
    """``(share, warning)`` where the model's ``A`` at the reference, ``sum_i h_i(x*) A_i``, is off by more than
    :data:`MISSED` in some state's rate of the plant's Jacobian ``df/dx`` there (:func:`row_shares`, the largest),
    the rest held in the premises and in ``B(x)`` times the reference input (see the module docstring); None where
    it is not, where the plant gives no reference, or where the reference lies outside the region.

    Measured (2026-11-29): a boost converter in absolute units is off by 0.5 in its current's rate, a synchronous
    generator (angle in rad) by 0.94 in its speed's, a building in kelvin by 0.3 in its water's, a quadrotor at
    hover by 0.95 in vx's; the plants written in deviations and the built-ins by 0 to round-off, a vehicle by 0.08,
    a motor arm by 0.04."""
    plant = ts.plant
    if ts.kind not in ("sector_auto", "sector") or (point := reference_point(plant)) is None:
        return None
    x_star, u_star = point
    J = _jacobian(plant, x_star, u_star)
    if not np.all(np.isfinite(J)):
        return None
    h = np.asarray(ts.memberships(x_star), dtype=float).ravel()
    A = sum(hi * np.asarray(lm.A, dtype=float) for hi, lm in zip(h, ts.local_models))
    shares = row_shares(J, A, _half_widths(plant))
    k = int(np.argmax(shares))
    share = float(shares[k])
    if share <= MISSED:
        return None
    where = "x_ref" if plant.x_ref is not None else "x = 0 with the reference input"
    unit = (
        f"{plant.state_units[k]} per {plant.time_unit}" if plant.state_units[k] else f"per {plant.time_unit}"
    )
    return share, (
        f"warning: the T-S model is written about x = 0, and at the plant's reference ({where}, the input "
        f"{np.round(u_star, 6).tolist()}) its A, sum_i h_i A_i, is off by {share:.2g} in the rate of "
        f"{plant.state_names[k]} (its row of df/dx there: [{_numbers(J[k])}] {unit} per unit of each state; the "
        "error of the model's row over the larger of the two, each state weighted by its half-width in the region: "
        "0 the same, 1 nothing in common): the rest lies in the premises and in the inputs' state-dependent "
        "coefficients times the reference input, which LMI (45) does not see (it certifies A_i + B_i K_j about x = "
        f"0), nor the observer as motion. {_advice(plant, x_star, u_star)}: there A carries it (it may take more "
        "premises: each coefficient then holds the reference too)"
    )
