"""``design(ts)``: the whole of Section 4.3 (steps 1-8) with certificates, as one call."""

from __future__ import annotations

import functools
import math
import time
from types import SimpleNamespace

import casadi as ca
import numpy as np
from threadpoolctl import threadpool_limits

from ..errors import AssumptionError, FteError, InfeasibleDesignError, ParameterError
from ..model.fingerprint import plant_fingerprint
from ..rounding import nice_ceil, nice_floor
from ..ts import TSModel, scheduling_from_measurements
from . import conditioned, paper
from .augment import augment
from .certify import certificate, discrete_certificate, failures
from .diagnose import FrontierPoint, gamma_min, sigma_max
from .limits import reachability
from .record import Design
from .records import Dims, Observer, Params
from .remark5 import explain_causes, with_remark5
from .remark5 import fallback as remark5_fallback
from .remark5 import record as remark5_record
from .uio import check_assumptions, enforce, uio_gain

__all__ = ["design", "explore", "GENERIC_DEFAULTS", "explain_45", "explain_46"]

GENERIC_DEFAULTS = {"gamma": 1.0, "gamma1": 0.5, "sigma": 1.0, "delta": 1e-4, "epsilon": 1e-4}
VARIANTS = ("paper", "conditioned")
#: the design defaults a plant may record from `fte tune` (beside the LMI parameters)
TUNED_KNOBS = ("alpha", "kappa", "boundary_layer", "bound_weight")
SOLVERS = ("CLARABEL", "SCS")


def _generic_scale(ts: TSModel, given: dict) -> tuple[float, dict]:
    """Factors for the generic gamma, gamma1 and sigma: they are taken in the outputs' own size ``sy`` (the
    power of two nearest the largest row norm of C, as :func:`~fte_casadi.design.augment.output_scale`).

    gamma bounds the gain from the unknown input to the outputs, so a number for it carries the outputs'
    units: the generic 1 asks a plant measured in mm for 1000 times the attenuation it asks of the same
    plant measured in m. (45) with outputs ``y / sy`` at ``(sigma, gamma, gamma1)`` is (45) with y at
    ``(sigma / sy^2, gamma sy, gamma1 sy)`` (:func:`~fte_casadi.design.augment.units_params`), and (46),
    (55), (64) and step 5's objective follow (:func:`~fte_casadi.design.conditioned._step5_problem`), so with
    the generic values taken in the outputs' own size a plant gets the same design whatever unit its outputs
    (and its sensor faults) are in: Pbar scaled by ``sy^2``, the gains L_i1 by ``1 / sy``, the same K, decay
    rate and largest sample time (``tests/test_slow_plant.py``; measured on a slow 4-state plant: in m it
    certifies at a sample time of 1 s, in mm, with the generic values as absolute numbers, it needed
    3.6e-4 s). gamma1 follows only a generic gamma (it stays below a gamma that was given). Values the user
    or the plant's defaults gave are kept; sy = 1 (every built-in plant) leaves everything as it is."""
    from .augment import output_size

    sy = output_size(ts.C)
    defaults = getattr(ts.plant, "design_defaults", {}) or {}
    generic = {k for k in ("gamma", "gamma1", "sigma") if given.get(k) is None and k not in defaults}
    if "gamma" not in generic:
        generic.discard("gamma1")
    scale = {"gamma": sy, "gamma1": sy, "sigma": sy**-2}
    return sy, {k: (scale[k] if k in generic else 1.0) for k in given}


def _params(ts: TSModel, given: dict, status: list) -> dict:
    plant_defaults = dict(getattr(ts.plant, "design_defaults", {}) or {})
    out = {}
    for k, v in given.items():
        if v is not None:
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ParameterError(f"{k} must be a positive finite number; got {v!r}")
            out[k] = float(v)
    sy, factor = _generic_scale(ts, given)
    for k in given:
        if k not in out:
            out[k] = float(plant_defaults.get(k, GENERIC_DEFAULTS[k] * factor[k]))
    scaled = sorted(k for k, f in factor.items() if f != 1.0)
    if scaled:
        status.append(
            f"generic values in the outputs' own size (C's largest row norm, as a power of two, is {sy:g}): "
            + ", ".join(f"{k} = {out[k]:g}" for k in scaled)
            + ", so that what they ask does not depend on the outputs' units"
        )
    if given["gamma1"] is None and out["gamma1"] >= out["gamma"]:
        ratio = plant_defaults.get("gamma1", GENERIC_DEFAULTS["gamma1"]) / plant_defaults.get(
            "gamma", GENERIC_DEFAULTS["gamma"]
        )
        out["gamma1"] = min(ratio, 0.5) * out["gamma"]
        status.append(
            f"gamma1 lowered to {out['gamma1']:g} (the default {ratio:g} * gamma) to keep gamma1 < gamma"
        )
    if out["gamma1"] >= out["gamma"]:
        raise ParameterError(
            f"gamma1 must be smaller than gamma (Theorem 2); got gamma1 = {out['gamma1']:g} >= gamma = {out['gamma']:g}"
        )
    return out


def _u_reference(ts: TSModel, K, status: list):
    plant = ts.plant
    if plant.u_ref is not None:
        return np.asarray(plant.u_ref, dtype=float).ravel(), None
    if plant.x_ref is None:
        return np.zeros(ts.m), None
    xr = np.asarray(plant.x_ref, dtype=float).ravel()
    F = plant.drift_function()
    u = ca.SX.sym("u", ts.m)
    g = F(xr, u, np.zeros(ts.ld), np.zeros(ts.lf))
    J = ca.Function("J", [u], [g, ca.jacobian(g, u)])
    ue = np.zeros(ts.m)
    for _ in range(50):  # Gauss-Newton on the drift at x_ref with d = f = 0
        r, Jm = (np.array(v) for v in J(ue))
        step = np.linalg.lstsq(Jm, -r.ravel(), rcond=None)[0]
        ue = ue + step
        if np.linalg.norm(step) < 1e-12 * (1 + np.linalg.norm(ue)):
            break
    res = float(np.linalg.norm(np.array(J(ue)[0])))
    lim = plant.input_limits
    if lim is not None and np.any((ue < lim[:, 0]) | (ue > lim[:, 1])):
        status.append(f"warning: the input holding x_ref, u_eq = {np.round(ue, 6).tolist()}, lies outside the input "
                      f"limits {np.asarray(lim).tolist()}: the loop saturates at rest")  # fmt: skip
    h = ts.memberships(xr)
    Kx = sum(h[j] * K[j] for j in range(len(K)))
    status.append(f"u_ref = u_eq - (sum_j h_j(x_ref) K_j) x_ref with u_eq = {np.round(ue, 6).tolist()} holding the "
                  f"nonlinear plant at x_ref (drift residual {res:.2g}); u = u_eq + K (xhat - x_ref)")  # fmt: skip
    return ue - Kx @ xr, xr


def _one_blas_thread(fn):
    """Run ``fn`` with the BLAS limited to one thread (threadpoolctl).

    The design's algebra is many small dense products and factorisations (matrices of tens of rows);
    a multi-threaded BLAS spends more on waking its threads than on the work, most of all on a loaded
    machine (docs/benchmarks.md). The limit is undone on return, and nested calls keep it.
    """

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with threadpool_limits(limits=1, user_api="blas"):
            return fn(*args, **kwargs)

    return wrapper


@_one_blas_thread
def design(
    ts: TSModel,
    *,
    variant: str = "conditioned",
    solver: str = "CLARABEL",
    gamma: float | None = None,
    gamma1: float | None = None,
    sigma: float | None = None,
    delta: float | None = None,
    epsilon: float | None = None,
    gamma2: float | None = None,
    alpha: float | None = None,
    sample_time: float | None = None,
    kappa: float | None = None,
    bound_weight: float | None = None,
    initial_state=None,
    allow_uncertified: bool = False,
    accept_assumptions=(),
    plant_spec: str | None = None,
    diagnose: bool = True,
    remark5: bool = True,
    d_bound=None,
    _retried: str | None = None,
) -> Design:
    """Design the sliding-mode UIO and fault-tolerant controller of ``ts`` (Section 4.3 / Theorem 5).

    Parameters left ``None`` come from ``ts.plant.design_defaults``, then from
    :data:`GENERIC_DEFAULTS`. ``variant="conditioned"`` (default) poses the printed LMIs so that
    the answer is unique and well scaled (:mod:`fte_casadi.design.conditioned`); ``"paper"``
    solves them as printed (:mod:`fte_casadi.design.paper`). ``alpha`` is the observer decay rate
    of the conditioned variant (default: a fraction of the largest feasible one, lowered so that
    ``ts_max >= 2 sample_time`` when ``sample_time`` is given); ``gamma2`` the d2 attenuation of
    Theorem 5 (default gamma). ``kappa`` bounds cond(X') and cond(Pbar) in the conditioned variant
    (default :data:`~fte_casadi.design.conditioned.KAPPA`; recorded in ``params`` when given).
    ``bound_weight`` (conditioned variant; default 0, off) puts the closed loop's fault-error bound into
    step 5's objective with that weight relative to the rest of it
    (:mod:`fte_casadi.design.bound_objective`; recorded in ``params`` when positive).
    ``initial_state`` is the nominal x(0) the simulations start from
    (default: the plant's), recorded as ``x0`` for the generated C's start from a first measurement.
    ``remark5`` (default True) applies Remark 5's fallback where H cannot decouple the unknown inputs
    (:mod:`fte_casadi.design.remark5`); ``d_bound`` (one number, or one per unknown input) bounds
    ``|d|`` in its sliding gain (default: delta, as printed). ``remark5=False`` refuses such a plant.
    Raises :class:`~fte_casadi.errors.InfeasibleDesignError` when an
    LMI is infeasible (with the bounds that are feasible, when ``diagnose``) or a certificate
    fails (unless ``allow_uncertified``), :class:`~fte_casadi.design.conditioned.SolverFailedError`
    when the solver fails numerically, :class:`~fte_casadi.errors.AssumptionError` when an
    assumption of Section 3 fails and is not in ``accept_assumptions``, and
    :class:`~fte_casadi.errors.ParameterError` on bad settings.

    Examples
    --------
    >>> from fte_casadi.plants import manipulator
    >>> from fte_casadi.ts import derive
    >>> d = design(derive(manipulator(), fidelity_samples=500))
    >>> d.certified, d.checks["lmi_max_eig"]["46"] < 0
    (True, True)
    """
    t0 = time.perf_counter()
    if variant not in VARIANTS:
        raise ParameterError(f"variant must be one of {VARIANTS}; got {variant!r}")
    solver = str(solver).upper()
    if solver not in SOLVERS:
        raise ParameterError(f"solver must be one of {SOLVERS}; got {solver!r}")
    status: list[str] = []
    params = _params(
        ts, {"gamma": gamma, "gamma1": gamma1, "sigma": sigma, "delta": delta, "epsilon": epsilon}, status
    )
    plant_defaults = getattr(ts.plant, "design_defaults", {}) or {}
    # the knobs `fte tune` finds, recorded in the plant's defaults
    tuned = {k: plant_defaults[k] for k in TUNED_KNOBS if k in plant_defaults}
    alpha_from_plant = alpha is None and "alpha" in tuned
    alpha = tuned.get("alpha") if alpha is None else alpha
    kappa = tuned.get("kappa") if kappa is None else kappa
    bound_weight = tuned.get("bound_weight") if bound_weight is None else bound_weight
    if "boundary_layer" in tuned:
        params["boundary_layer"] = float(tuned["boundary_layer"])
    if tuned:
        status.append(
            "from the plant's design defaults: " + ", ".join(f"{k} = {v:g}" for k, v in tuned.items())
        )
    generic = {k for k, v in (("gamma", gamma), ("sigma", sigma)) if v is None and k not in plant_defaults}
    if gamma2 is not None:
        params["gamma2"] = _params(
            ts, {"gamma": gamma2, "gamma1": None, "sigma": None, "delta": None, "epsilon": None}, []
        )["gamma"]
    if kappa is not None:
        if (
            isinstance(kappa, bool)
            or not isinstance(kappa, (int, float))
            or not math.isfinite(kappa)
            or kappa <= 1
        ):
            raise ParameterError(
                f"kappa (the bound on cond(Pbar)) must be a finite number above 1; got {kappa!r}"
            )
        params["kappa"] = float(kappa)
    if bound_weight is not None:
        if (
            isinstance(bound_weight, bool)
            or not isinstance(bound_weight, (int, float))
            or not (math.isfinite(bound_weight) and bound_weight >= 0)
        ):
            raise ParameterError(
                f"bound_weight (the fault-error bound's weight in step 5's objective) must be a finite number >= 0; "
                f"got {bound_weight!r}"
            )
        if bound_weight > 0:
            params["bound_weight"] = float(bound_weight)
    for name, v in (("alpha", alpha), ("sample_time", sample_time)):
        if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0
                              or (name == "sample_time" and v == 0)):  # fmt: skip
            raise ParameterError(
                f"{name} must be a {'positive' if name == 'sample_time' else 'non-negative'} finite number; got {v!r}"
            )
    aug = augment(ts.local_models, ts.C, ts.Df)
    theorem5 = any(lm.has_diffusion_extension for lm in ts.local_models)
    if theorem5:
        params.setdefault("gamma2", params["gamma"])
        status.append(
            "Theorem 5: faults/inputs/d2 in the diffusion, LMIs (78)-(81) (keys 45/46/55/64 hold the same values)"
        )
    H, T = uio_gain(aug)
    checks_a = check_assumptions(aug, T)
    r5 = remark5_fallback(aug, checks_a, remark5)
    if r5 is not None:  # Remark 5: H decouples what it can, the sliding term attenuates the rest
        H, T, aug = r5.H, r5.T, with_remark5(aug, r5)
        checks_a = check_assumptions(aug, T, remark5=r5)
    checks_a = explain_causes(_named(checks_a, aug, ts.plant), aug, ts.plant, remark5)
    try:
        status += enforce(checks_a, accept_assumptions)
    except AssumptionError as exc:
        raise AssumptionError(str(exc) + _scaling_note(ts)) from None
    r5doc = {} if r5 is None else remark5_record(r5, d_bound, params, ts.plant.unknown_input_names)
    status += [r5doc["message"]] if r5doc else []
    if not all(c.holds for c in checks_a):
        generic = set()  # a plant that fails an assumption gets the bounds, not a search over parameters
    retry = dict(variant=variant, solver=solver, gamma=gamma, gamma1=gamma1, sigma=sigma, delta=delta, epsilon=epsilon,
                 gamma2=gamma2, alpha=alpha, sample_time=sample_time, accept_assumptions=accept_assumptions,
                 kappa=kappa, bound_weight=bound_weight, remark5=remark5, d_bound=d_bound, plant_spec=plant_spec, initial_state=initial_state)  # fmt: skip
    if variant == "paper":
        s3, K = paper.step3(aug, params, solver)
        s5 = paper.step5(aug, params, s3.X, K, T, solver)
        status.append(
            "paper variant: problem as printed (with the corrections of docs/method.md); expect an ill-conditioned Pbar"
        )
    else:
        try:
            try:
                if "sigma" in generic and all(c.holds for c in checks_a):
                    # the generic sigma is often outside what a plant's (45) allows, and a conic solver takes
                    # long to say so (24-state chain at sigma = 1: SCS 45 s); the bound is one solve that the
                    # parameter search needs anyway, and only a definite bound is taken as a refusal here
                    smax, st = sigma_max(aug, params["gamma"], params["gamma1"], solver)
                    if smax is None and st in ("optimal", "infeasible"):  # solved: no sigma > 0 at all
                        raise InfeasibleDesignError(
                            f"LMI (45) is infeasible: no sigma > 0 makes it feasible at gamma = {params['gamma']:g}"
                        )
                    if smax is not None and params["sigma"] >= smax:
                        raise InfeasibleDesignError(
                            f"LMI (45) is infeasible: sigma = {params['sigma']:g} is above the largest sigma "
                            f"{smax:.3g} it allows at gamma = {params['gamma']:g}"
                        )
                s3 = conditioned.step3(aug, params, solver)
            except conditioned.SolverFailedError as exc:
                beyond = _outside_45(aug, params, solver)
                if beyond is None:
                    return _other_solver(ts, retry, solver, exc, "step 3 (LMI (45))",
                                         allow_uncertified=allow_uncertified, diagnose=diagnose,
                                         retried=_retried)  # fmt: skip
                raise InfeasibleDesignError(beyond) from None
        except InfeasibleDesignError as exc:
            refused: list = []
            chosen = (
                _choose(ts, aug, params, solver, retry, generic, "45", exc, refused) if diagnose else None
            )
            if chosen is not None:
                return chosen
            raise (explain_45(ts, aug, params, solver, retry, refused) if diagnose else exc) from None
        K = [s3.K] * aug.r
        try:
            view = _closed_loop_view(ts, T, K, r5doc) if params.get("bound_weight") else None
            s5 = conditioned.step5(aug, params, s3.X, s3.K, T, solver, alpha=alpha, sample_time=sample_time,
                                   bound_view=view, alpha_is_default=alpha_from_plant)  # fmt: skip
        except conditioned.SolverFailedError as exc:
            return _other_solver(ts, retry, solver, exc, "step 5 (LMIs (46), (55), (64))", allow_uncertified=allow_uncertified,
                                 diagnose=diagnose, retried=_retried)  # fmt: skip
        except InfeasibleDesignError as exc:
            if diagnose and "alpha" not in str(exc) and "sample time" not in str(exc):
                refused = []
                chosen = _choose(ts, aug, params, solver, retry, generic, "46", exc, refused)
                if chosen is not None:
                    return chosen
                raise explain_46(ts, aug, params, solver, retry, exc, refused) from None
            raise
    status += s3.notes + s5.notes
    X = s3.X
    P = np.linalg.inv(X)
    L1 = [np.linalg.solve(s5.Pbar, Q) for Q in s5.Q]
    R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
    L2 = [Ri @ H for Ri in R]
    Ls = T @ aug.Js  # T J1, or T [Bdbar_u J1] with Remark 5
    Kf, Kf_rules = _fault_gains(ts, status)
    point = dict(X=X, K=K, P=P, T=T, Pbar=s5.Pbar, Q=s5.Q, N=s5.N, theta=s5.theta, R=R, L1=L1)
    checks = certificate(aug, point, params)
    if sample_time is not None:  # the step that runs: z+ = z + Ts (...), checked with Pbar for any blending
        checks["discrete"] = discrete_certificate(R, s5.Pbar, float(sample_time))
    checks["assumptions"] = [c.to_dict() for c in checks_a]
    # the plant's region (null: a state without bounds): the generated C checks y against its image
    checks["region"] = {
        side: [None if np.isnan(v) else float(v) for v in vals]
        for side, vals in (("lo", ts.plant.region_lo), ("hi", ts.plant.region_hi))
    }
    checks["alpha"] = float(s5.alpha)
    bad = failures(checks)
    certified = not bad
    if bad:
        what = "; ".join(bad)
        hint = (
            "use variant='conditioned'"
            if variant == "paper"
            else "raise sigma, or lower alpha, or try solver='SCS'"
        )
        msg = f"the design is not certified at the returned point: {what} does not hold; {hint}"
        if not allow_uncertified:
            raise InfeasibleDesignError(msg, result=checks)
        status.append("NOT CERTIFIED: " + msg)
    u_ref, x_ref = _u_reference(ts, K, status)
    sched, sources = scheduling_from_measurements(ts)
    plant = ts.plant
    total = time.perf_counter() - t0
    observer = {k: (float(v) if isinstance(v, (int, float, np.floating)) and v is not None else v)
                for k, v in s5.observer.items()}  # fmt: skip
    return Design(
        plant=plant.name,
        plant_spec=plant_spec or plant.name,
        variant=variant,
        solver=solver,
        params=Params.from_mapping(params),
        dims=Dims.from_mapping(
            {"n": ts.n, "m": ts.m, "p": ts.p, "ld": ts.ld, "lf": ts.lf, "r": ts.r, "nbar": aug.nbar}
        ),
        premises=[p.to_dict() for p in ts.premises],
        local_models=ts.local_models,
        C=np.array(ts.C, dtype=float),
        Df=np.array(ts.Df, dtype=float),
        H=H,
        T=T,
        X=X,
        P=P,
        K=tuple(K),
        Kf=Kf,
        Kf_rules=Kf_rules,
        Pbar=s5.Pbar,
        Q=tuple(s5.Q),
        N=s5.N,
        theta=float(s5.theta),
        L1=tuple(L1),
        L2=tuple(L2),
        R=tuple(R),
        Ls=Ls,
        checks=checks,
        timings={"total_s": total, "solver_s": s3.seconds + s5.seconds},
        u_ref=u_ref,
        x_ref=x_ref,
        scheduling=sched,  # the record keeps it as data (scheduling_ops) and, for older readers, serialised
        plant_hash=plant_fingerprint(plant),
        names={
            "states": list(plant.state_names),
            "inputs": list(plant.input_names),
            "outputs": list(plant.output_names),
            "faults": list(plant.fault_names),
            "state_units": list(plant.state_units),
            "output_units": list(plant.output_units),
            "scheduling_sources": sources,
        },  # fmt: skip
        certified=certified,
        status=status,
        solves={"step3": int(s3.solves), "step5": int(s5.solves), "total": int(s3.solves + s5.solves)},
        observer=Observer.from_mapping(observer),
        input_limits=None if plant.input_limits is None else np.array(plant.input_limits, dtype=float),
        x0=_initial_state(plant, initial_state),
        bounds=_bounds(certified, R, K, Kf, Kf_rules, T, ts, u_ref, r5doc, getattr(s5, "bound", None)),
        remark5=r5doc,
    )


def _scaling_note(ts: TSModel) -> str:
    """Where the local models' coefficients span more than 1e10, a sentence saying that the rank decisions
    behind an assumption's verdict are made at a tolerance relative to the largest one ('' otherwise)."""
    big, small, where = 0.0, np.inf, ""
    for i, lm in enumerate(ts.local_models):
        for key in ("A", "B", "Bd", "Bf"):
            M = np.abs(np.asarray(lm[key], dtype=float))
            nz = M[M > 1e-12 * M.max()] if M.size else M  # not the round-off of an exact zero
            if nz.size and nz.max() > big:
                k = np.unravel_index(np.argmax(M), M.shape)
                big, where = (
                    float(nz.max()),
                    f"{key}[{k[0] + 1}, {k[1] + 1}] = {float(lm[key][k]):.3g} in rule {i + 1}",
                )
            if nz.size:
                small = min(small, float(nz.min()))
    if not (big > 0 and small < np.inf and big / small > 1e10):
        return ""
    return (
        f" Note: the plant's coefficients span a factor {big / small:.1e} (largest {where}, "
        f"smallest {small:.3g}); the rank decisions behind this verdict use a tolerance relative to the largest, so "
        "it may come from that scaling rather than from the plant's structure: rescale its units (states, inputs) "
        "so that its coefficients lie within about 1e6 of each other, and design again."
    )


def _fault_gains(ts: TSModel, status: list):
    """``(Kf, Kf_rules)``: the fault compensation ``Kf_i = -pinv(B_i) Bf_i``, one for all rules when they agree."""
    Kfs = [-np.linalg.pinv(lm.B) @ lm.Bf for lm in ts.local_models]
    Kf, Kf_rules = Kfs[0], None
    # B_i and Bf_i may both vary (an actuator fault enters where u does: Bf = B E) and still give one Kf
    spread = max(float(np.max(np.abs(Ki - Kfs[0]))) for Ki in Kfs)
    if spread > 1e-9 * max(1.0, float(np.max(np.abs(Kfs[0])))):
        Kf_rules = tuple(Kfs)
        status.append(f"Kf scheduled: -pinv(B_i) Bf_i differs between rules (by up to {spread:.3g}); the step blends "
                      "Kf(h) = sum_i h_i Kf_i (document: Kf_rules; Kf is rule 1's)")  # fmt: skip
    return Kf, Kf_rules


def _closed_loop_view(ts: TSModel, T, K, r5doc, gains=None, u_ref=None, **known):
    """The closed loop's data the bound needs (:mod:`fte_casadi.design.bounds`), or None where it is not posed
    (Remark 5's fallback, Theorem 5's diffusion). ``gains = (Kf, Kf_rules)`` and ``u_ref`` once the design has
    them (before step 5 they are computed here, their messages left to the design); ``known``: ``R`` once the
    observer is designed."""
    if (r5doc and r5doc.get("used")) or any(lm.has_diffusion_extension for lm in ts.local_models):
        return None
    scratch: list = []
    Kf, Kf_rules = _fault_gains(ts, scratch) if gains is None else gains
    u_ref = _u_reference(ts, K, scratch)[0] if u_ref is None else u_ref
    return SimpleNamespace(dims=SimpleNamespace(n=ts.n, lf=ts.lf), T=T, u_ref=u_ref, Kf=Kf, Kf_rules=Kf_rules, r=ts.r,
                           local_models=ts.local_models, K=K, **known)  # fmt: skip


def _bounds(certified, R, K, Kf, Kf_rules, T, ts, u_ref, r5doc, fallback=None) -> dict:
    """The certified bounds on the fault- and state-estimation errors at the returned design
    (:mod:`fte_casadi.design.bounds`), for a certified design; {} otherwise."""
    if not certified:
        return {}
    if r5doc and r5doc.get("used"):
        why = {"holds": False, "why": "not computed where Remark 5's fallback is used"}
        return {"fault_error": why, "state_error": dict(why)}
    from .bounds import fault_error_bound, state_error_bound

    view = _closed_loop_view(ts, T, K, None, (Kf, Kf_rules), u_ref, R=R)
    if view is None:  # Theorem 5's diffusion: the bounds say so
        view = SimpleNamespace(local_models=ts.local_models)
    fe = fault_error_bound(view, fallback=fallback)
    return {"fault_error": fe, "state_error": state_error_bound(view, start=fe)}


def _outside_45(aug, params: dict, solver: str) -> str | None:
    """Why (45) is infeasible at ``params`` by its bounds (one SDP each, well posed), or None.

    The conditioned step 3 is homogeneous in its unknowns, so an infeasible (45) can end in a solver's
    numerical failure rather than a certificate of infeasibility; before the other solver is tried (SCS
    takes minutes to fail there), the bounds decide whether the parameters lie outside what (45) allows.
    """
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    smax, _ = sigma_max(aug, g, g1, solver)
    if smax is None:
        return f"LMI (45) is infeasible: no sigma > 0 makes it feasible at gamma = {g:g}"
    if sg >= smax:
        return f"LMI (45) is infeasible: sigma = {sg:g} is above the largest sigma {smax:.3g} it allows at gamma = {g:g}"
    return None


def _other_solver(ts, retry: dict, solver: str, exc: Exception, where: str, *, retried, **kw) -> Design:
    """A numerical failure of one solver is retried with the other before it is reported; the
    design's status says so, and a failure of both names both."""
    other = SOLVERS[1 - SOLVERS.index(solver)]
    if retried:
        raise conditioned.SolverFailedError(
            f"both solvers failed numerically: first {retried.rstrip('.')}; then {solver} in {where}: "
            f"{str(exc).rstrip('.')}. See the feasible region with `fte design PLANT --explore`, or rescale the "
            "plant's units"
        ) from None
    d = design(ts, **(dict(retry) | {"solver": other}), _retried=f"{solver} in {where}: {exc}", **kw)
    d.status.insert(0, f"{solver} failed numerically in {where} ({' '.join(str(exc).split())[:200]}); "
                       f"designed with {other} instead")  # fmt: skip
    return d


#: fractions of the largest feasible sigma tried, in order, when the tool chooses sigma itself
SIGMA_TRIALS = (0.8, 0.6, 0.4, 0.2, 0.1, 0.05)
#: multiples of the smallest feasible gamma tried when the tool chooses gamma itself
GAMMA_TRIALS = (1.25, 1.6, 2.5, 4.0, 10.0)


def _choose(ts, aug, params: dict, solver: str, retry: dict, generic: set, lmi: str, exc,
            refused: list | None = None) -> Design | None:  # fmt: skip
    """Parameters the tool finds itself: when sigma and/or gamma came from the generic
    defaults (neither the user nor the plant set them) and the design fails at them, the feasibility
    bounds say where to look: sigma below the largest sigma (45) allows, else gamma above the smallest
    one it allows. The first value tried that gives a certified design is taken, and the document's
    ``params_chosen`` says what was chosen and why. None when nothing was generic or nothing tried works."""
    import dataclasses

    if not generic:
        return None
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]

    def trials():  # lazily: each bound is one conic solve, asked for only when the values before it failed
        if "sigma" in generic:
            smax, _ = sigma_max(aug, g, g1, solver)
            if smax is not None:
                if lmi == "45":
                    cands = [nice_floor(smax * f) for f in SIGMA_TRIALS]
                else:  # (46) wants sigma large enough to dominate the observer-loop coupling
                    cands = [
                        nice_floor(sg + f * (smax - sg)) for f in (0.2, 0.4, 0.6, 0.8, 0.95) if smax > sg
                    ]
                    cands += [nice_floor(smax * f) for f in SIGMA_TRIALS]
                why = f"the largest sigma for which (45) is feasible at gamma = {g:g}, gamma1 = {g1:g} is {smax:.3g}"
                yield from (({"sigma": c}, why) for c in dict.fromkeys(cands) if c > 0)
        if {"sigma", "gamma"} <= generic and sigma_max(aug, g, g1, solver)[0] is None:
            sup, _ = sigma_max(aug, None, g1, solver)  # no sigma works at this gamma: move both
            for f in (0.5, 0.2, 0.05) if sup is not None else ():
                sc = nice_floor(sup * f)
                gm, _ = gamma_min(aug, sc, g1, solver)
                if gm is None:
                    continue
                why = (f"no sigma makes (45) feasible at gamma = {g:g}; any gamma needs sigma < {sup:.3g}, and at "
                       f"sigma = {sc:g} the smallest feasible gamma is {gm:.3g}")  # fmt: skip
                yield from (
                    ({"sigma": sc, "gamma": nice_ceil(max(gm * gf, g1 * 1.01))}, why) for gf in (1.25, 2.5)
                )
        if "gamma" in generic:
            gmin, _ = gamma_min(aug, sg, g1, solver)
            if gmin is not None:
                why = f"the smallest gamma for which (45) is feasible at sigma = {sg:g}, gamma1 = {g1:g} is {gmin:.3g}"
                yield from (({"gamma": nice_ceil(max(gmin * f, g1 * 1.01))}, why) for f in GAMMA_TRIALS)

    for change, why in trials():
        d = _try(ts, retry, refused, **change)
        if d is not None:
            first = " ".join(str(exc).split())[:160]
            chosen = {k: {"value": v, "why": f"the generic default {params[k]:g} failed ({first}); {why}; "
                          f"{k} = {v:g} is the first value tried that gives a certified design"}
                      for k, v in change.items()}  # fmt: skip
            notes = [f"{k} = {c['value']:g} chosen by the tool: {c['why']}" for k, c in chosen.items()]
            return dataclasses.replace(d, params_chosen=chosen, status=notes + list(d.status))
    return None


def _named(checks: list, aug, plant) -> list:
    """The failed assumptions (1) and (2) with the faults and unknown inputs behind them named, and the
    measurement that would separate them (:mod:`fte_casadi.design.structure`)."""
    import dataclasses

    from .structure import describe

    out = []
    for c in checks:
        if not c.holds and c.name in ("(1)", "(2)"):
            why = describe(aug, plant, {c.name})
            if why:
                c = dataclasses.replace(c, message=f"{c.message}. Which: {why}")
        out.append(c)
    return out


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


def _try(ts, retry: dict, refused: list | None = None, **change) -> Design | None:
    """The whole design with some parameters changed, or None when it does not give a certified design
    (then ``(change, why)`` is appended to ``refused``, when given)."""
    kw = dict(retry) | change
    try:
        d = design(ts, diagnose=False, **kw)
    except FteError as exc:
        if refused is not None:
            refused.append((change, " ".join(str(exc).split())))
        return None
    if not d.certified and refused is not None:
        refused.append((change, "not certified"))
    return d if d.certified else None


def _refusals(refused: list) -> str:
    """What stopped the values tried (the first of each kind), for the refusal's message: a bound can be
    right and the design still fail at it for another reason (e.g. the sample time)."""
    seen, out = set(), []
    for change, why in refused:
        kind = why[:40]
        if kind in seen:
            continue
        seen.add(kind)
        at = ", ".join(f"{k} = {v:g}" for k, v in change.items())
        out.append(f"at {at}: {why[:700]}")
    return (" The values tried were refused for other reasons: " + "; ".join(out[:2]) + ".") if out else ""


def explain_45(
    ts, aug, params: dict, solver: str, retry: dict, refused: list | None = None
) -> InfeasibleDesignError:
    """The error for an infeasible (45): the smallest feasible gamma and the largest feasible sigma,
    each followed by a value that was tried and gives a certified design."""
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    gmin, _ = gamma_min(aug, sg, g1, solver)
    smax, _ = sigma_max(aug, g, g1, solver)
    parts, fixes = [], []
    if gmin is None:
        sup, _ = sigma_max(aug, None, g1, solver)
        parts.append(f"no gamma makes (45) feasible at sigma = {sg:g}"
                     + (f" (any gamma needs sigma < {sup:.3g})" if sup else ""))  # fmt: skip
        if sup is None and (why := reachability(aug)):
            parts.append(why)
    else:
        given = {k: retry.get(k) for k in ("gamma", "gamma1", "sigma")}
        default_g1 = (getattr(ts.plant, "design_defaults", {}) or {}).get(
            "gamma1", GENERIC_DEFAULTS["gamma1"] * _generic_scale(ts, given)[1]["gamma1"]
        )
        lowered = retry.get("gamma1") is None and not math.isclose(g1, float(default_g1), rel_tol=1e-12)
        parts.append(
            f"the smallest gamma for which (45) is feasible with gamma1 = {g1:g}"
            + (
                " (the default gamma1, lowered with gamma to stay below it; --gamma1 sets it)"
                if lowered
                else ""
            )
            + f", sigma = {sg:g} is {gmin:.3g}"
        )
        for f in (1.05, 1.25, 1.6, 2.5, 4.0):
            cand = nice_ceil(max(gmin * f, g1 * 1.01))
            if _try(ts, retry, refused, gamma=cand) is not None:
                fixes.append(f"raise gamma to >= {cand:g}")
                break
    if smax is None:
        parts.append(f"no sigma > 0 makes it feasible at gamma = {g:g}")
    else:
        parts.append(f"the largest sigma for which it is feasible with gamma = {g:g} is {smax:.3g}")
        for f in (0.95, 0.8, 0.6, 0.4, 0.2, 0.1):
            cand = nice_floor(smax * f)
            if _try(ts, retry, refused, sigma=cand) is not None:
                fixes.append(f"lower sigma to <= {cand:g}")
                break
    checked = "each checked: it gives" if len(fixes) > 1 else "checked: it gives"
    advice = (
        (" or ".join(fixes) + f" ({checked} a certified design)")
        if fixes
        else (
            "no value tried gives a certified design: see `fte design PLANT --explore` for the feasible frontier"
        )
    )
    return InfeasibleDesignError(
        f"LMI (45) is infeasible: {'; '.join(parts)}. {advice[0].upper() + advice[1:]}."
        + ("" if fixes else _refusals(refused or []))
    )


def explain_46(ts, aug, params: dict, solver: str, retry: dict, exc: Exception,
               refused: list | None = None) -> InfeasibleDesignError:  # fmt: skip
    """The error for an infeasible (46) at alpha = 0: a larger sigma (within what (45) allows) that works."""
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    smax, _ = sigma_max(aug, g, g1, solver)
    fix = None
    if smax is not None and smax > sg:
        for f in (0.2, 0.4, 0.6, 0.8, 0.95):
            cand = nice_floor(sg + f * (smax - sg))
            if cand > sg and _try(ts, retry, refused, sigma=cand) is not None:
                fix = cand
                break
    msg = (f"{str(exc).rstrip('.')}. The -sigma I block of (46) must dominate the coupling of the observer with the loop; (45) allows "
           f"sigma up to {smax:.3g} at gamma = {g:g}." if smax else f"{exc}")  # fmt: skip
    msg += (
        f" Raise sigma to {fix:g} (checked: it gives a certified design)."
        if fix
        else (
            " No larger sigma tried gives a certified design: see `fte design PLANT --explore`."
            + _refusals(refused or [])
        )
    )
    return InfeasibleDesignError(msg)


#: gammas tried above the frontier of (45), as multiples of its smallest gamma
LADDER = (1.05, 1.25, 1.6, 2.5, 4.0, 6.3, 10.0)


def explore(ts, *, solver: str = "CLARABEL", gamma1: float | None = None, sigmas=None, count: int = 12,
            sample_time: float | None = None, progress=None) -> tuple[list[FrontierPoint], dict]:  # fmt: skip
    """The feasible frontier: for each sigma, the smallest gamma for which (45) is feasible, and the
    smallest gamma of :data:`LADDER` x that value for which the whole design (both steps and the
    certificate) is certified: step 5 needs some room above the frontier of (45).

    ``sigmas`` default: ``count`` values spaced in log scale from ``min(sigma / 30, 1e-3 sigma_sup)``
    (``sigma`` the plant's default) to just below ``sigma_sup``, the largest sigma any gamma allows. Returns the points and a dict with the plant's default parameters and that sigma bound.
    """
    status: list[str] = []
    params = _params(
        ts, {"gamma": None, "gamma1": gamma1, "sigma": None, "delta": None, "epsilon": None}, status
    )
    aug = augment(ts.local_models, ts.C, ts.Df)
    g1 = params["gamma1"]
    sup, _ = sigma_max(aug, None, g1, solver)
    if sigmas is None:
        if sup is None:
            raise InfeasibleDesignError(
                f"LMI (45) is infeasible for every gamma and sigma with gamma1 = {g1:g}: the loop cannot be made to "
                "dominate the plant's diffusion with this output; check W_i and C"
            )
        sigmas = np.geomspace(min(params["sigma"] / 30, sup * 1e-3), sup * 0.98, count)
    points = []
    for k, sg in enumerate(sigmas):
        gmin, _ = gamma_min(aug, float(sg), g1, solver)
        if gmin is None:
            points.append(
                FrontierPoint(float(sg), None, None, False, None, None, "(45) infeasible for every gamma")
            )
        else:
            point, why = None, ""
            for f in LADDER:  # the smallest gamma on the ladder whose whole design is certified
                gt = nice_ceil(max(f * gmin, 1.01 * g1))
                try:
                    d = design(
                        ts,
                        diagnose=False,
                        solver=solver,
                        gamma=gt,
                        gamma1=g1,
                        sigma=float(sg),
                        sample_time=sample_time,
                    )
                except FteError as exc:
                    why = " ".join(str(exc).split())[:100]
                    continue
                if d.certified:
                    point = FrontierPoint(
                        float(sg),
                        gmin,
                        gt,
                        True,
                        d.observer.alpha,
                        d.checks["max_abs_L1"],
                        ts_max=d.checks["ts_max"],
                    )
                    break
            points.append(point or FrontierPoint(float(sg), gmin, None, False, None, None, f"no gamma up to "
                                                 f"{LADDER[-1]:g} x {gmin:.3g} certifies: {why}"))  # fmt: skip
        if progress is not None:
            progress(k + 1, len(sigmas))
    return points, {"gamma": params["gamma"], "gamma1": g1, "sigma": params["sigma"], "sigma_sup": sup}
