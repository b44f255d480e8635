"""``design(ts)``: the whole of Section 4.3 (steps 1-8) with certificates, as one call.

The call is one frozen record of options (:class:`~fte_casadi.design._options.DesignOptions`) run through the
pipeline of :mod:`~fte_casadi.design._pipeline`; where a stage fails, the diagnosis
(:mod:`fte_casadi.design.diagnose`) tries the record changed (the parameter search), says what failed and what
was checked to work, and names the cause behind it. A refusal is read by its record's fields
(:class:`~fte_casadi.errors.Refusal`), never by its message.
"""

from __future__ import annotations

import dataclasses
import functools
import time

import numpy as np
from threadpoolctl import threadpool_limits

from .._progress import note, stage
from .._text import shorten
from ..errors import FteError, InfeasibleDesignError, ParameterError, Refused
from ..ts import TSModel, as_model
from . import _pipeline as pipeline
from . import diagnose
from ._model_form import missed_motion
from ._options import SOLVERS, DesignOptions, _params, gamma_size, resolve, round_gamma
from ._record import Design
from .core import _conditioned as conditioned
from .core._diagnose import FrontierPoint, gamma_min, sigma_max

__all__ = ["design", "explore"]


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
def design(ts: TSModel, options: DesignOptions | None = None, **changes) -> Design:
    """Design the sliding-mode UIO and fault-tolerant controller of ``ts`` (Section 4.3 / Theorem 5).

    ``options`` is a :class:`~fte_casadi.design._options.DesignOptions` (default: all defaults); keyword
    arguments are its fields and change it (``design(ts, sigma=0.2)`` is
    ``design(ts, DesignOptions(sigma=0.2))``). Parameters left ``None`` come from
    ``ts.plant.design_defaults``, then from :data:`GENERIC_DEFAULTS`, afresh in every retry.
    ``variant="conditioned"`` (default) poses the printed LMIs so that the answer is unique and well
    scaled (:mod:`fte_casadi.design.core._conditioned`); ``"paper"`` solves them as printed
    (:mod:`fte_casadi.design.core._paper`). See :class:`~fte_casadi.design._options.DesignOptions` for
    every field.

    When the design fails at parameters that came from the generic defaults, the tool searches sigma and
    gamma (``params_chosen`` says what it chose); when one solver fails numerically, the other is tried.

    Raises :class:`~fte_casadi.errors.InfeasibleDesignError` when an
    LMI is infeasible (with the bounds that are feasible, when ``diagnose``) or a certificate
    fails (unless ``allow_uncertified``), :class:`~fte_casadi.errors.SolverFailedError`
    when both solvers fail numerically, :class:`~fte_casadi.errors.AssumptionError` when an
    assumption of Section 3 fails and is not in ``accept_assumptions``, and
    :class:`~fte_casadi.errors.ParameterError` on bad settings.

    Examples
    --------
    >>> from fte_casadi.plants import manipulator
    >>> from fte_casadi.ts import derive
    >>> d = design(derive(manipulator(), fidelity_samples=500), DesignOptions(sample_time=1e-3))
    >>> d.certified, d.checks["lmi_max_eig"]["46"] < 0
    (True, True)
    """
    options = DesignOptions(**changes) if options is None else options.replace(**changes)
    return _attempt(as_model(ts, "design()"), options)


@_one_blas_thread
def design_at_rate_fraction(ts: TSModel, fraction: float, options: DesignOptions | None = None,
                            **changes) -> Design:  # fmt: skip
    """``design(ts, options, alpha=fraction * a0)``, ``a0`` the observer decay rate ``design(ts, options)`` takes by
    default (``fte tune``'s knob ``alpha_scale``). ``a0`` is read from steps 1-5 as the design makes them (its
    kappa, its loop and its sample time included), without the certificate and the bounds of a design that is not
    kept, and the second design reuses the first's step 3 (:func:`~._pipeline.step3_reused`). Where a step fails
    at the default rate, the whole design is made there (its other solver, its diagnosis), and raises as it does;
    a design without a decay rate (the paper variant) is returned as it is."""
    options = DesignOptions(**changes) if options is None else options.replace(**changes)
    ts = as_model(ts, "design_at_rate_fraction()")
    with pipeline.step3_reused():
        a0, d = _rate_or_design(ts, options)
        if a0 is None:
            return d
        return _attempt(ts, options.replace(alpha=float(fraction) * a0))


def default_observer_rate(ts: TSModel, options: DesignOptions | None = None, **changes) -> float | None:
    """``a0`` of :func:`design_at_rate_fraction`: the observer decay rate the design takes by default, read the same
    way (steps 1-5, else the whole design); None where the design fails or has no decay rate."""
    options = DesignOptions(**changes) if options is None else options.replace(**changes)
    try:
        return _rate_or_design(as_model(ts, "default_observer_rate()"), options)[0]
    except FteError:
        return None


def _rate_or_design(ts: TSModel, options: DesignOptions) -> tuple[float | None, Design | None]:
    """``(a0, None)`` with ``a0`` the default observer rate of steps 1-5; where a step fails there, the whole design
    (its other solver, its diagnosis; raised where it fails) and its rate: ``(alpha or None, design)``."""
    a0 = _default_rate(ts, options)
    if a0 is not None:
        return a0, None
    d = _attempt(ts, options)
    return (None if d.observer.alpha is None else float(d.observer.alpha)), d


def _default_rate(ts: TSModel, options: DesignOptions) -> float | None:
    """The observer decay rate of steps 1-5 at ``options`` (no retry, no search); None where a step fails or the
    variant has none."""
    if options.variant == "paper":
        return None
    try:
        res = resolve(ts, options)
        st = pipeline.structure(ts, options, res)
        s3 = pipeline.loop(ts, st, res, options.solver, search=options.diagnose)
        _, s5 = pipeline.loop_then_observer(ts, st, options, res, s3)
    except FteError:
        return None
    return float(s5.alpha)


def _attempt(ts: TSModel, options: DesignOptions, retried: str | None = None) -> Design:
    """One design of ``ts`` with ``options``: the pipeline, and where a stage fails the other solver
    (``retried``: the failure of the first), the parameter search and the diagnosis."""
    t0 = time.perf_counter()
    res = resolve(ts, options)
    st = pipeline.structure(ts, options, res)
    # a plant that fails an assumption gets the bounds, not a search over parameters
    generic = res.generic if st.assumptions_hold else frozenset()
    solver, params = options.solver, res.params
    if options.variant == "paper":
        s3, K, s5 = pipeline.paper_steps(st, res, solver)
        return pipeline.finish(ts, options, res, st, s3, K, s5, t0)
    note(f"step 3: the gain K by LMI (45) at {_at(params)}")
    try:
        try:
            if "sigma" in generic:
                _refuse_beyond_sigma_max(st.aug, params, solver)
            s3 = pipeline.loop(ts, st, res, solver, search=options.diagnose)
        except conditioned.SolverFailedError as exc:
            beyond = diagnose.beyond_sigma_max(st.aug, params, solver)
            if beyond is None:
                return _other_solver(ts, options, exc, "step 3 (LMI (45))", "45", retried)
            raise InfeasibleDesignError(beyond) from None
    except InfeasibleDesignError as exc:
        if not options.diagnose:
            raise exc from None
        refused: list = []
        chosen = diagnose.choose(_attempt, ts, options, st.aug, params, generic, "45", exc, refused)
        if chosen is not None:
            return chosen
        raise _explained(ts, options, st, params, refused, "45", exc) from None
    note(f"step 5: the observer by LMI (46) at {_at(params)}, its decay rate and kappa searched")
    try:
        s3, s5 = pipeline.loop_then_observer(ts, st, options, res, s3)
    except conditioned.SolverFailedError as exc:
        return _other_solver(ts, options, exc, "step 5 (LMIs (46), (55), (64))", "46", retried)
    except InfeasibleDesignError as exc:
        if not options.diagnose or exc.refusal.kind in ASKED:
            raise
        refused = []
        chosen = diagnose.choose(_attempt, ts, options, st.aug, params, generic, "46", exc, refused)
        if chosen is not None:
            return chosen
        raise _explained(ts, options, st, params, refused, "46", exc) from None
    return pipeline.finish(ts, options, res, st, s3, [s3.K] * st.aug.r, s5, t0)


#: refusals of what was asked for (a decay rate, a sample time, a settling window): the parameter search and the
#: diagnosis of sigma and gamma do not answer them, so they are raised as they are
ASKED = (Refused.DECAY_RATE, Refused.SAMPLE_TIME, Refused.SETTLE)


def _explained(ts: TSModel, options: DesignOptions, st, params: dict, refused: list, lmi: str,
               exc: InfeasibleDesignError) -> InfeasibleDesignError:  # fmt: skip
    """The refusal of ``lmi`` ("45" or "46") at ``params`` with its bounds, the advice checked, and its cause named
    (:mod:`fte_casadi.design.diagnose`); ``refused``: the values the parameter search tried."""
    with stage(f"diagnosis of the refusal by ({lmi}): its bounds, its advice checked"):
        if lmi == "45":
            err = diagnose.explain_45(_attempt, ts, options, st.aug, params, refused)
        else:
            err = diagnose.explain_46(_attempt, ts, options, st.aug, params, exc, refused)
        err = diagnose.name_cause(_attempt, err, ts, options, st, params, refused, lmi)
    if (missed := missed_motion(ts)) is None:
        return err
    # the LMIs refused the model about x = 0, which at the reference is off from the plant: say so beside the cause
    r = err.refusal
    form = missed[1].removeprefix("warning: ")
    return InfeasibleDesignError(dataclasses.replace(r, detail=f"{r.detail}. {form}" if r.detail else form))


def _at(params: dict) -> str:
    """The parameters a progress note names: sigma and gamma."""
    return ", ".join(f"{k} = {params[k]:.3g}" for k in ("sigma", "gamma") if params.get(k) is not None)


def _refuse_beyond_sigma_max(aug, params: dict, solver: str) -> None:
    """Refuse a generic sigma outside what (45) allows before step 3 is solved.

    The generic sigma is often outside what a plant's (45) allows, and a conic solver takes long to say so
    (24-state chain at sigma = 1: SCS 45 s); the bound is one solve that the parameter search needs anyway,
    and only a decided bound is taken as a refusal here."""
    refusal = diagnose.beyond_sigma_max(aug, params, solver, decided=True)
    if refusal is not None:
        raise InfeasibleDesignError(refusal)


def _other_solver(
    ts, options: DesignOptions, exc: Exception, where: str, lmi: str, retried: str | None
) -> Design:
    """A numerical failure of one solver is retried with the other (the same record, its solver changed)
    before it is reported; the design's status says so, and a failure of both names both (``lmi``: the LMI of
    the step ``where`` that failed)."""
    solver = options.solver
    other = SOLVERS[1 - SOLVERS.index(solver)]
    if getattr(exc, "solver_independent", False):  # numpy's stages would fail the same with the other solver
        raise exc
    if retried:
        raise conditioned.SolverFailedError(
            f"both solvers failed numerically: first {retried.rstrip('.')}; then {solver} in {where}: "
            f"{str(exc).rstrip('.')}. See the feasible region with `fte design PLANT --explore`, or rescale the "
            "plant's units",
            lmi=lmi,
        ) from None
    d = _attempt(ts, options.replace(solver=other), retried=f"{solver} in {where}: {exc}")
    d.status.insert(0, f"{solver} failed numerically in {where} ({shorten(exc, 200)}); "
                       f"designed with {other} instead")  # fmt: skip
    return d


#: gammas tried above the frontier of (45), as multiples of its smallest gamma
LADDER = (1.05, 1.25, 1.6, 2.5, 4.0, 6.3, 10.0)


def explore(ts, options: DesignOptions | None = None, *, sigmas=None, count: int = 12, progress=None,
            budget: float | None = 60.0, **changes) -> tuple[list[FrontierPoint], dict]:  # fmt: skip
    """The feasible frontier: for each sigma, the smallest gamma for which (45) is feasible, and the
    smallest gamma of :data:`LADDER` x that value for which the whole design (both steps and the
    certificate) is certified: step 5 needs some room above the frontier of (45).

    ``options`` is the :class:`~fte_casadi.design._options.DesignOptions` of a design (keyword arguments are its
    fields and change it, as for :func:`design`): every design along the frontier is made with it (variant,
    solver, gamma1, delta, epsilon, alpha, kappa, bound_weight, sample_time, initial_state, accepted assumptions,
    Remark 5, plant_spec), gamma and sigma excepted, which the frontier searches: giving either is refused, as is
    ``allow_uncertified`` (the frontier counts certified designs only), with
    :class:`~fte_casadi.errors.ParameterError`.

    ``sigmas`` default: ``count`` values spaced in log scale from ``min(sigma / 30, 1e-3 sigma_sup)``
    (``sigma`` the plant's default) to just below ``sigma_sup``, the largest sigma any gamma allows. Returns the
    points and a dict with the plant's default parameters, that sigma bound, ``best`` (the certified design
    with the fastest observer, None without one; where no point is certified and no kappa was given, the design
    at the plant's defaults, which searches kappa as :func:`design` does, if it is certified: ``best_from`` says
    so) and ``cause`` (why none is certified, when the diffusion is
    why: :func:`~fte_casadi.design.diagnose.tolerance`). ``budget`` (seconds, None: none): sigmas not reached
    within it are listed as not tried, and said so in ``info["skipped"]``.
    """
    from ._augment import augment
    from ._uio import uio_gain

    ts = as_model(ts, "explore()")
    options = DesignOptions(**changes) if options is None else options.replace(**changes)
    given = [k for k in ("gamma", "sigma") if getattr(options, k) is not None]
    if given:
        raise ParameterError(
            f"the frontier searches gamma and sigma itself; {' and '.join(given)} cannot be given to it (design at "
            "them without exploring, or leave them out)"
        )
    if options.allow_uncertified:
        raise ParameterError(
            "the frontier counts certified designs only, and its best design is certified: allow_uncertified "
            "(--allow-uncertified) means nothing to it"
        )
    solver, gamma1 = options.solver, options.gamma1
    t0 = time.perf_counter()
    status: list[str] = []
    params = _params(
        ts,
        {"gamma": None, "gamma1": gamma1, "sigma": None, "delta": options.delta, "epsilon": options.epsilon},
        status,
    )
    aug = augment(ts.local_models, ts.C, ts.Df)
    g1 = params["gamma1"]
    sup, _ = sigma_max(aug, None, g1, solver)
    if sigmas is None:
        if sup is None:
            raise InfeasibleDesignError(
                f"LMI (45) is infeasible for every gamma and sigma with gamma1 = {g1:g}: the loop cannot be made to "
                "dominate the plant's diffusion with this output; check W_i and C",
                lmi="45",
            )
        sigmas = np.geomspace(min(params["sigma"] / 30, sup * 1e-3), sup * 0.98, count)
    gs = gamma_size(ts)
    base = options.replace(diagnose=False, gamma1=g1)
    points, best, skipped, refused_46 = [], None, 0, None
    # the largest sigma first ((46) asks for a large one, (45) for a small one), within 70 % of the budget: the
    # rest is left for the diagnosis of a frontier without a certified design
    for k, sg in enumerate(sorted(sigmas, reverse=True)):
        if budget is not None and time.perf_counter() - t0 > 0.7 * budget:
            points.append(
                FrontierPoint(
                    float(sg), None, None, False, None, None, f"not tried: the {budget:g} s budget ran out"
                )
            )
            skipped += 1
            if progress is not None:
                progress(k + 1, len(sigmas))
            continue
        gmin, _ = gamma_min(aug, float(sg), g1, solver)
        if gmin is None:
            points.append(
                FrontierPoint(float(sg), None, None, False, None, None, "(45) infeasible for every gamma")
            )
        else:
            point, why, tried = None, "", set()
            for f in LADDER:  # the smallest gamma on the ladder whose whole design is certified
                gt = round_gamma(max(f * gmin, 1.01 * g1), gs)
                if gt in tried:  # without unknown inputs gamma bounds nothing: one design tells
                    continue
                tried.add(gt)
                try:
                    d = design(ts, base.replace(gamma=gt, sigma=float(sg)))
                except FteError as exc:
                    why = shorten(exc, 100)
                    if (
                        getattr(exc, "lmi", None) == "46" and refused_46 is None
                    ):  # step 3 passed: (46) refused it
                        refused_46 = dict(params, gamma=gt, sigma=float(sg), gamma1=g1)
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
                    if best is None or d.observer.alpha > best.observer.alpha:
                        best = d
                    break
            what = (f"no gamma up to {LADDER[-1]:g} x {gmin:.3g} certifies" if gmin > 0 else
                    "no design certifies (gamma bounds no unknown input here)")  # fmt: skip
            points.append(point or FrontierPoint(float(sg), gmin, None, False, None, None, f"{what}: {why}"))
        if progress is not None:
            progress(k + 1, len(sigmas))
    points.sort(key=lambda pt: pt.sigma)
    cause, best_from = None, None
    if best is None and options.kappa is None and (budget is None or time.perf_counter() - t0 < budget):
        # the grid's designs keep cond(X'), cond(Pbar) <= the default kappa (no search of it: it doubled a refusal's
        # time); the plant's own design searches kappa, and a plant certified only under a larger one (a levitation)
        # would be told that nothing certifies
        try:
            d = design(ts, options)
        except FteError:
            d = None
        if d is not None and d.certified:
            best = d
            best_from = (f"the design at the plant's defaults, with kappa = {d.params.kappa:g} (fte design searches "
                         f"kappa; the frontier's grid keeps the default bound)")  # fmt: skip
    if (
        best is None and refused_46 is not None
    ):  # the causes of a refusal (diagnose.name_cause), decided the same way
        _, T = uio_gain(aug)
        at = {"sigma": float(f"{refused_46['sigma']:.3g}"), "gamma": refused_46["gamma"]}
        found = diagnose.blocking_diffusion(aug, T, refused_46, at) or diagnose.weak_faults(
            ts, refused_46, at
        )
        cause = found.render() if found is not None else None
    return points, {"gamma": params["gamma"], "gamma1": g1, "sigma": params["sigma"], "sigma_sup": sup,
                    "best": best, "best_from": best_from, "cause": cause, "skipped": skipped}  # fmt: skip
