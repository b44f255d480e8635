"""Model fidelity: the blended T-S drift/diffusion against the nonlinear plant."""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..errors import IntegrationStopped
from ._direct import direct
from ._model import Fidelity

__all__ = ["blended", "fidelity", "sample_box"]


def sample_box(plant, N: int, rng: np.random.Generator) -> dict[str, np.ndarray]:
    """Random states in the region (states without bounds: x0 +- max(1, |x0|)), inputs about
    the reference, unknown inputs and faults in [-1, 1]."""
    lo, hi = plant.region_lo.copy(), plant.region_hi.copy()
    free = np.isnan(lo)
    span = np.maximum(1.0, np.abs(plant.x0))
    lo[free], hi[free] = plant.x0[free] - span[free], plant.x0[free] + span[free]
    x = lo[:, None] + (hi - lo)[:, None] * rng.random((plant.n, N))
    uc = plant.u_ref if plant.u_ref is not None else np.zeros(plant.m)
    if plant.operating_inputs is not None:
        uc = plant.operating_inputs.mean(axis=0)
    us = np.maximum(1.0, np.abs(uc))
    u = uc[:, None] + us[:, None] * (2 * rng.random((plant.m, N)) - 1)
    d = 2 * rng.random((plant.ld, N)) - 1
    f = 2 * rng.random((plant.lf, N)) - 1
    d2 = 2 * rng.random((plant.d2.numel(), N)) - 1
    return {"x": x, "u": u, "d": d, "f": f, "d2": d2}


def blended(ts, x, u, d, f, d2) -> tuple[np.ndarray, np.ndarray]:
    """Blended T-S drift and diffusion at columns of samples."""
    h = ts.memberships(x)  # (r, N)
    drift = np.zeros_like(x)
    diff = np.zeros_like(x)
    for i, lm in enumerate(ts.local_models):
        drift += h[i] * (lm.A @ x + lm.B @ u + lm.Bd @ d + lm.Bf @ f + lm.a[:, None])
        diff += h[i] * (lm.W @ x + lm.G @ u + lm.Gf @ f + (lm.M @ d2 if lm.M.size else 0.0))
    return drift, diff


def fidelity(
    ts, samples: int = 20_000, seed: int = 0, horizon: float | None = None, points: int = 400
) -> Fidelity:
    """Largest drift/diffusion error over ``samples`` random points of the region, and along
    an open-loop trajectory of the nonlinear plant from x0 under the reference input; for a sector
    model, up to the point where a premise leaves its bounds (the memberships saturate there and
    the model is not claimed; ``trajectory_points`` and ``trajectory_horizon`` say how much was kept)."""
    plant = ts.plant
    ef, eg, scale = _sampled_errors(ts, samples, seed)
    # trajectory: open loop under the reference (or equilibrium) input, no noise
    uc = _reference_input(plant)
    f1 = plant.drift_function()
    zd, zf = np.zeros(plant.ld), np.zeros(plant.lf)
    if horizon is None:
        horizon = _default_horizon(ts)
    # start off the reference, a fifth of the region's span away, so the trajectory sweeps the region
    lo, hi = plant.region_lo, plant.region_hi
    start = plant.x0 + np.where(np.isnan(lo), 0.0, 0.2 * (np.nan_to_num(hi) - np.nan_to_num(lo)))
    start = np.where(np.isnan(lo), start, np.clip(start, np.nan_to_num(lo), np.nan_to_num(hi)))
    xs = ca.SX.sym("x", plant.n)
    f_open = ca.Function("open_loop", [xs], [f1(xs, uc, zd, zf)])
    drift = direct(f_open)
    X, T, stop = _trajectory(
        lambda t, x: drift(x)[0],
        start,
        horizon,
        points,
        plant.region_lo,
        plant.region_hi,
    )
    if ts.premises and ts.kind in ("sector", "sector_auto"):
        X, T, stop = _within_premises(ts, X, T, stop)
    M = X.shape[1]
    U = np.tile(uc[:, None], (1, M))
    tf = np.array(f1.map(M)(X, U, np.zeros((plant.ld, M)), np.zeros((plant.lf, M))))
    tg = np.array(
        plant.diffusion_function().map(M)(X, U, np.zeros((plant.lf, M)), np.zeros((plant.d2.numel(), M)))
    )
    bf2, bg2 = blended(
        ts, X, U, np.zeros((plant.ld, M)), np.zeros((plant.lf, M)), np.zeros((plant.d2.numel(), M))
    )
    et = float(max(np.max(np.abs(tf - bf2)), np.max(np.abs(tg - bg2))))
    return Fidelity(
        max_abs_error=max(ef, eg),
        samples=samples,
        drift_max_abs_error=ef,
        diffusion_max_abs_error=eg,
        drift_max_rel_error=ef / scale,
        trajectory_max_abs_error=et,
        trajectory_points=M,
        trajectory_horizon=float(T[-1]) if M < points else float(horizon),
        trajectory_stop=stop,
    )


def _sampled_errors(ts, samples: int, seed: int) -> tuple[float, float, float]:
    """The largest drift and diffusion errors of the model over ``samples`` random points of the region, and
    the largest drift there (1 when it is zero: the scale of the relative error)."""
    plant = ts.plant
    rng = np.random.default_rng(seed)
    s = sample_box(plant, samples, rng)
    fd = plant.drift_function().map(samples)
    fg = plant.diffusion_function().map(samples)
    true_f = np.array(fd(s["x"], s["u"], s["d"], s["f"]))
    true_g = np.array(fg(s["x"], s["u"], s["f"], s["d2"]))
    bf, bg = blended(ts, s["x"], s["u"], s["d"], s["f"], s["d2"])
    ef = float(np.max(np.abs(true_f - bf)))
    eg = float(np.max(np.abs(true_g - bg)))
    return ef, eg, float(np.max(np.abs(true_f))) or 1.0


def _reference_input(plant) -> np.ndarray:
    """The open loop's input: the operating input nearest the reference state (local linearisation), else the
    reference input (or zero)."""
    if plant.operating_inputs is not None:
        j = plant.scheduling_state
        xr = (
            plant.x_ref
            if plant.x_ref is not None
            else plant.operating_points[len(plant.operating_points) // 2]
        )
        k = int(np.argmin(np.abs(plant.operating_points[:, j] - xr[j])))
        return plant.operating_inputs[k]
    return plant.u_ref if plant.u_ref is not None else np.zeros(plant.m)


def _default_horizon(ts) -> float:
    """Three of the local models' slowest time constants, within [1, 1000] (10 when every A is zero)."""
    lam = max(np.max(np.abs(np.linalg.eigvals(lm.A))) for lm in ts.local_models)
    slow = min(
        (abs(v.real) for lm in ts.local_models for v in np.linalg.eigvals(lm.A) if abs(v.real) > 1e-9),
        default=1.0,
    )
    return float(np.clip(3.0 / slow, 1.0, 1000.0)) if lam > 0 else 10.0


def _within_premises(ts, X: np.ndarray, T: np.ndarray, stop: str | None) -> tuple:
    """The trajectory up to the first point where a premise leaves its bounds (or its group's polytope): a sector
    model is exact only within them (outside, the memberships saturate); ``stop`` says where, when it does."""
    Z = np.array(ts.premise_fn.map(X.shape[1])(X)).reshape(len(ts.premises), -1)
    mn = np.array([p.min for p in ts.premises])[:, None]
    mx = np.array([p.max for p in ts.premises])[:, None]
    tol = 1e-9 * np.maximum(np.abs(mn), np.abs(mx))  # relative: premises in any unit
    within = (Z >= mn - tol) & (Z <= mx + tol)  # (premises, points)
    for g in ts.groups:  # and within the polytope of each group
        if g.polytope != "box":
            within[list(g.premises)] &= g.inside(Z[list(g.premises)])[None, :]
    inside = np.all(within, axis=0)
    keep = max(1, X.shape[1] if np.all(inside) else int(np.argmin(inside)))
    if keep < X.shape[1]:
        k = int(np.argmin(inside))
        bad = ts.premises[int(np.argmin(within[:, k]))]
        stop = (
            f"the open loop leaves the region: premise {bad.expr} leaves its bounds [{bad.min:.4g}, {bad.max:.4g}] "
            f"or its group's polytope by t = {T[k]:.4g}, beyond which the model is not claimed"
            + (f"; later {stop}" if stop else "")
        )
    return X[:, :keep], T[:keep], stop


#: right-hand-side evaluations allowed for the fidelity trajectory, per method (RK45: 6 per step)
MAX_EVALUATIONS = 60_000
#: how far (in region spans) the open loop may wander before the trajectory stops
ESCAPE = 1000.0
#: evaluations beyond the budget an integrator's last step may take (RK45: 6 per trial step, LSODA's
#: Jacobian n + 1) before it is stopped in the middle of that step
_STEP_SLACK = 256


def _trajectory(fun, start, horizon, points, lo, hi, max_evaluations=MAX_EVALUATIONS):
    """The open-loop trajectory by RK45 (as ``solve_ivp`` would), and by LSODA, which switches to a
    stiff method, where RK45 spends a third of the budget (see :func:`_integrate`; the built-in plants
    and examples take 300-4300 evaluations)."""
    from scipy.integrate import LSODA, RK45  # here: loading fte_casadi does not wait for scipy.integrate

    spent = [0]
    X, T, stop = _integrate(RK45, fun, start, horizon, points, lo, hi, max_evaluations // 3, spent)
    if spent[0] > max_evaluations // 3:  # RK45 spent its budget: stiff
        X2, T2, stop2 = _integrate(LSODA, fun, start, horizon, points, lo, hi, max_evaluations)
        if T2[-1] > T[-1]:
            return X2, T2, stop2
    return X, T, stop


def _integrate(method, fun, start, horizon, points, lo, hi, max_evaluations, spent: list | None = None):
    """Integrate ``x' = fun(t, x)`` from ``start`` by ``method`` (rtol 1e-8, atol 1e-10) and return its values
    at ``points`` equally spaced times of ``[0, horizon]`` (the same as ``solve_ivp`` with ``t_eval``),
    up to where it stops early, and why it did ("" if it did not).

    It stops when a state is ``ESCAPE`` spans of its region away from the region's centre (a state
    without bounds: ``ESCAPE max(1, |start|)`` from 0) or not finite -- an unstable open loop escaping,
    possibly in finite time, which an adaptive integrator would otherwise chase with ever smaller
    steps -- and when ``max_evaluations`` right-hand sides have been spent (a stiff plant over a long
    horizon). ``spent`` (a one-element list, if given) counts the right-hand sides evaluated."""
    t_eval = np.linspace(0.0, horizon, points)
    x_start = np.asarray(start, float)
    spent = [0] if spent is None else spent

    def rhs(t, xx):
        # every trial step of the integrator comes through here, also the ones its inner loop
        # rejects while shrinking the step: the budget bounds that loop too, and a non-finite
        # right-hand side ends it at once (a step size it would otherwise shrink towards 0)
        spent[0] += 1
        if spent[0] > max_evaluations + _STEP_SLACK:
            raise IntegrationStopped(
                f"stiff: {max_evaluations} evaluations spent by t = {t:.4g} ({method.__name__})"
            )
        v = fun(t, xx)
        if not np.all(np.isfinite(v)):
            raise IntegrationStopped(
                f"the drift is not finite at t = {t:.4g} (x = {np.array2string(np.asarray(xx), precision=4)})"
            )
        return v

    free = np.isnan(lo)
    centre = np.where(free, 0.0, 0.5 * (np.nan_to_num(lo) + np.nan_to_num(hi)))
    scale = np.where(free, np.maximum(1.0, np.abs(start)), np.nan_to_num(hi) - np.nan_to_num(lo))
    times, ys, i, stop = [], [], 0, ""
    try:
        solver = method(rhs, 0.0, x_start, horizon, rtol=1e-8, atol=1e-10)
    except IntegrationStopped as exc:
        return x_start[:, None], np.zeros(1), str(exc)
    while solver.status == "running":
        try:
            solver.step()
        except IntegrationStopped as exc:
            stop = str(exc)
            break
        if solver.status == "failed":
            stop = f"the integrator failed at t = {solver.t:.4g}"
            break
        j = int(np.searchsorted(t_eval, solver.t, side="right"))
        if j > i:
            times.append(t_eval[i:j])
            ys.append(solver.dense_output()(t_eval[i:j]))
            i = j
        y = solver.y
        if not np.all(np.isfinite(y)) or np.any(np.abs(y - centre) > ESCAPE * scale):
            stop = f"the open loop escapes (beyond {ESCAPE:g} region spans by t = {solver.t:.4g})"
        elif solver.status == "running" and solver.nfev > max_evaluations:
            stop = f"stiff: {max_evaluations} evaluations spent by t = {solver.t:.4g} ({method.__name__})"
        if stop:  # keep where it got to (beyond the last equally spaced time)
            if np.all(np.isfinite(y)) and (not times or solver.t > times[-1][-1]):
                times.append(np.array([solver.t]))
                ys.append(np.asarray(y, float)[:, None])
            break
    if not times:
        return x_start[:, None], np.zeros(1), stop
    return np.hstack(ys), np.hstack(times), stop
