"""``design(ts)``: the whole of Section 4.3 (steps 1-8) with certificates, as one call.

The call is one frozen record of options (:class:`~fte_casadi.design._options.DesignOptions`) run through the
pipeline of :mod:`~fte_casadi.design._pipeline`; where a stage fails, the parameter search
(:mod:`~fte_casadi.design._search`) tries the record changed, and the diagnosis
(:mod:`~fte_casadi.design._explain`) says what failed and what was checked to work.
"""

from __future__ import annotations

import functools
import time

import numpy as np
from threadpoolctl import threadpool_limits

from .._text import shorten
from ..errors import FteError, InfeasibleDesignError
from ..ts import TSModel
from . import _diffusion as diffusion
from . import _necessary as necessary
from . import _pipeline as pipeline
from . import _separability as separability
from ._cover import other_cover
from ._explain import explain_45, explain_46, outside_45
from ._options import GENERIC_DEFAULTS, SOLVERS, DesignOptions, _params, gamma_size, resolve, round_gamma
from ._record import Design
from ._search import choose, try_design
from .core import _conditioned as conditioned
from .core._diagnose import FrontierPoint, gamma_min, sigma_max

__all__ = ["design", "explore", "DesignOptions", "GENERIC_DEFAULTS"]


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
    return _attempt(ts, options)


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
    try:
        try:
            if "sigma" in generic:
                _refuse_beyond_sigma_max(st.aug, params, solver)
            s3 = pipeline.step3(st, res, solver)
        except conditioned.SolverFailedError as exc:
            beyond = outside_45(st.aug, params, solver)
            if beyond is None:
                return _other_solver(ts, options, exc, "step 3 (LMI (45))", retried)
            raise InfeasibleDesignError(beyond) from None
    except InfeasibleDesignError as exc:
        if not options.diagnose:
            raise exc from None
        refused: list = []
        chosen = choose(_attempt, ts, options, st.aug, params, generic, "45", exc, refused)
        if chosen is not None:
            return chosen
        raise _naming_cause(explain_45(_attempt, ts, options, st.aug, params, refused), ts, options, st,
                               params, refused, "45") from None  # fmt: skip
    try:
        s3, s5 = pipeline.loop_then_observer(ts, st, options, res, s3)
    except conditioned.SolverFailedError as exc:
        return _other_solver(ts, options, exc, "step 5 (LMIs (46), (55), (64))", retried)
    except InfeasibleDesignError as exc:
        if options.diagnose and "alpha" not in str(exc) and "sample time" not in str(exc):
            refused = []
            chosen = choose(_attempt, ts, options, st.aug, params, generic, "46", exc, refused)
            if chosen is not None:
                return chosen
            raise _naming_cause(explain_46(_attempt, ts, options, st.aug, params, exc, refused), ts, options,
                                   st, params, refused, "46") from None  # fmt: skip
        raise
    return pipeline.finish(ts, options, res, st, s3, [s3.K] * st.aug.r, s5, t0)


#: the solver the causes of a refusal are decided with (:func:`_naming_cause`)
DECIDING_SOLVER = "CLARABEL"


def _naming_cause(err: InfeasibleDesignError, ts: TSModel, options: DesignOptions, st, params: dict,
                  refused: list, lmi: str) -> InfeasibleDesignError:  # fmt: skip
    """``err`` with its cause named, where one is found, at the parameters tried where (45) held (else the given
    ones): the diffusion (:func:`~._diffusion.tolerance`: the fraction of it the design tolerates, and whether
    the whole design certifies with the diffusion scaled to that fraction, run, not guessed), else, where (46)
    fails, a fault the outputs tell apart only weakly (:func:`~._separability.blocking`), else the cover's
    vertices where another cover gives a certified design (:func:`~._cover.other_cover`)."""
    at = next((change for change, why in refused if "(46)" in why), {})
    p = dict(params, **at)
    where = ", ".join(f"{k} = {p[k]:g}" for k in ("sigma", "gamma", "gamma1"))
    msg = str(err).split(" No value tried")[0].split(" No larger sigma tried")[0].rstrip(".")
    # the causes are decisions about the LMIs: made with the interior-point solver (and phase 1 in numpy where
    # it fails), whichever solver the design asked for; SCS's first-order answers near the boundary decide less
    tol = diffusion.tolerance(st.aug, st.T, p, DECIDING_SOLVER)
    if tol is None or not tol.blocks:
        if (at or lmi == "46") and not st.r5doc and (found := separability.blocking(ts, p, DECIDING_SOLVER)):
            text = separability.text(found, where)
            return InfeasibleDesignError(f"{msg}. {text[0].upper() + text[1:]}.")
        if text := other_cover(_attempt, ts, options):
            return InfeasibleDesignError(f"{msg}. {text[0].upper() + text[1:]}.")
        return err
    text = f"{tol.text()} at {where}"
    if found := necessary.limits(st.aug, DECIDING_SOLVER):  # where no design of any structure could do better
        text += (f". It is the plant, not the method: {necessary.describe(found)} (a necessary condition for any "
                 "design; docs/method.md)")  # fmt: skip
    fix = ""
    if tol.feasible > 0:
        why: list = []
        d = try_design(_attempt, diffusion.scaled_model(ts, tol.feasible), options, why, **at)
        fix = (
            f" With the diffusion scaled by {tol.feasible:.3g} the whole design is certified (checked): if the "
            "plant's noise is smaller than written, write it as it is; otherwise this method cannot certify an "
            "observer for it at the parameters tried."
            if d is not None
            else f" Even with the diffusion scaled by {tol.feasible:.3g} the whole design is not certified: "
            f"{shorten(why[0][1], 300) if why else 'not certified'}."
        )
    return InfeasibleDesignError(f"{msg}. {text[0].upper() + text[1:]}.{fix}")


def _refuse_beyond_sigma_max(aug, params: dict, solver: str) -> None:
    """Refuse a generic sigma outside what (45) allows before step 3 is solved.

    The generic sigma is often outside what a plant's (45) allows, and a conic solver takes long to say so
    (24-state chain at sigma = 1: SCS 45 s); the bound is one solve that the parameter search needs anyway,
    and only a definite bound is taken as a refusal here."""
    smax, st = sigma_max(aug, params["gamma"], params["gamma1"], solver)
    if smax is None and (st in ("optimal", "infeasible") or st.startswith("phase 1")):  # no sigma > 0 at all
        raise InfeasibleDesignError(
            f"LMI (45) is infeasible: no sigma > 0 makes it feasible at gamma = {params['gamma']:g}"
        )
    if smax is not None and params["sigma"] >= smax:
        raise InfeasibleDesignError(
            f"LMI (45) is infeasible: sigma = {params['sigma']:g} is above the largest sigma "
            f"{smax:.3g} it allows at gamma = {params['gamma']:g}"
        )


def _other_solver(ts, options: DesignOptions, exc: Exception, where: str, retried: str | None) -> Design:
    """A numerical failure of one solver is retried with the other (the same record, its solver changed)
    before it is reported; the design's status says so, and a failure of both names both."""
    solver = options.solver
    other = SOLVERS[1 - SOLVERS.index(solver)]
    if getattr(exc, "solver_independent", False):  # numpy's stages would fail the same with the other solver
        raise exc
    if retried:
        raise conditioned.SolverFailedError(
            f"both solvers failed numerically: first {retried.rstrip('.')}; then {solver} in {where}: "
            f"{str(exc).rstrip('.')}. See the feasible region with `fte design PLANT --explore`, or rescale the "
            "plant's units"
        ) from None
    d = _attempt(ts, options.replace(solver=other), retried=f"{solver} in {where}: {exc}")
    d.status.insert(0, f"{solver} failed numerically in {where} ({shorten(exc, 200)}); "
                       f"designed with {other} instead")  # fmt: skip
    return d


#: gammas tried above the frontier of (45), as multiples of its smallest gamma
LADDER = (1.05, 1.25, 1.6, 2.5, 4.0, 6.3, 10.0)


def explore(ts, *, solver: str = "CLARABEL", gamma1: float | None = None, sigmas=None, count: int = 12,
            sample_time: float | None = None, progress=None, budget: float | None = 60.0,
            ) -> tuple[list[FrontierPoint], dict]:  # fmt: skip
    """The feasible frontier: for each sigma, the smallest gamma for which (45) is feasible, and the
    smallest gamma of :data:`LADDER` x that value for which the whole design (both steps and the
    certificate) is certified: step 5 needs some room above the frontier of (45).

    ``sigmas`` default: ``count`` values spaced in log scale from ``min(sigma / 30, 1e-3 sigma_sup)``
    (``sigma`` the plant's default) to just below ``sigma_sup``, the largest sigma any gamma allows. Returns the
    points and a dict with the plant's default parameters, that sigma bound, ``best`` (the certified design
    with the fastest observer, None without one) and ``cause`` (why none is certified, when the diffusion is
    why: :func:`~fte_casadi.design._diffusion.tolerance`). ``budget`` (seconds, None: none): sigmas not reached
    within it are listed as not tried, and said so in ``info["skipped"]``.
    """
    from ._augment import augment
    from ._uio import uio_gain

    t0 = time.perf_counter()
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
    gs = gamma_size(ts)
    base = DesignOptions(diagnose=False, solver=solver, gamma1=g1, sample_time=sample_time)
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
            point, why = None, ""
            for f in LADDER:  # the smallest gamma on the ladder whose whole design is certified
                gt = round_gamma(max(f * gmin, 1.01 * g1), gs)
                try:
                    d = design(ts, base.replace(gamma=gt, sigma=float(sg)))
                except FteError as exc:
                    why = shorten(exc, 100)
                    if "(46)" in why and refused_46 is None:
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
            points.append(point or FrontierPoint(float(sg), gmin, None, False, None, None, f"no gamma up to "
                                                 f"{LADDER[-1]:g} x {gmin:.3g} certifies: {why}"))  # fmt: skip
        if progress is not None:
            progress(k + 1, len(sigmas))
    points.sort(key=lambda pt: pt.sigma)
    cause = None
    if (
        best is None and refused_46 is not None
    ):  # the causes of a refusal (_naming_cause), decided the same way
        _, T = uio_gain(aug)
        where = f"sigma = {refused_46['sigma']:.3g}, gamma = {refused_46['gamma']:g}"
        tol = diffusion.tolerance(aug, T, refused_46, DECIDING_SOLVER)
        if tol is not None and tol.blocks:
            cause = f"{tol.text()} at {where}"
        elif found := separability.blocking(ts, refused_46, DECIDING_SOLVER):
            cause = separability.text(found, where)
    return points, {"gamma": params["gamma"], "gamma1": g1, "sigma": params["sigma"], "sigma_sup": sup,
                    "best": best, "cause": cause, "skipped": skipped}  # fmt: skip
