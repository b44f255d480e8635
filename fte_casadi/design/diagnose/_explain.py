"""The diagnosis of a design that fails: which LMI, which bounds are feasible, and a value that was checked
to give a certified design (each suggestion is a whole design run at it: :func:`~._parameters.try_design`).
Each returns a :class:`~fte_casadi.errors.Refusal`, its numbers in ``numbers``."""

from __future__ import annotations

import dataclasses
import math

from ..._rounding import nice_floor
from ...errors import InfeasibleDesignError, Refusal, Refused
from .._limits import reachability
from .._options import DesignOptions, default_gamma1, gamma_size, round_gamma
from ..core._conditioned import KAPPA, SolverFailedError, step3
from ..core._diagnose import DECIDED, gamma_min, sigma_max
from ._parameters import Attempt, first_of_each_kind, try_design

__all__ = []


def beyond_sigma_max(aug, params: dict, solver: str, *, decided: bool = False) -> Refusal | None:
    """The refusal of (45) at ``params`` by its bound on sigma (one SDP, well posed), or None where sigma is
    within it.

    The conditioned step 3 is homogeneous in its unknowns, so an infeasible (45) can end in a solver's numerical
    failure rather than a certificate of infeasibility, and a conic solver takes long to say so (24-state chain at
    sigma = 1: SCS 45 s); the bound decides whether the parameters lie outside what (45) allows. ``decided``:
    "no sigma at all" only on a bound its solve decided (:data:`~fte_casadi.design.core._diagnose.DECIDED`), not
    on one that failed."""
    g, sg = params["gamma"], params["sigma"]
    smax, status = sigma_max(aug, g, params["gamma1"], solver)
    if smax is None and (not decided or status in DECIDED):
        return Refusal(Refused.LMI, f"LMI (45) is infeasible: no sigma > 0 makes it feasible at gamma = {g:g}",
                       lmi="45", numbers={"gamma": g})  # fmt: skip
    if smax is not None and sg >= smax:
        return Refusal(Refused.LMI, f"LMI (45) is infeasible: sigma = {sg:g} is above the largest sigma {smax:.3g} it "
                       f"allows at gamma = {g:g}", lmi="45", numbers={"sigma": sg, "gamma": g, "sigma_max": smax})  # fmt: skip
    return None


def explain_45(attempt: Attempt, ts, options: DesignOptions, aug, params: dict,
               refused: list | None = None) -> InfeasibleDesignError:  # fmt: skip
    """The error for an infeasible (45): the smallest feasible gamma and the largest feasible sigma,
    each followed by a value that was tried and gives a certified design."""
    solver = options.solver
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    gmin, _ = gamma_min(aug, sg, g1, solver)
    smax, _ = sigma_max(aug, g, g1, solver)
    numbers = {"sigma": sg, "gamma": g, "gamma1": g1}
    parts, fixes = [], []
    if gmin is None:
        sup, _ = sigma_max(aug, None, g1, solver)
        if sup is not None and smax is not None and smax > sup:
            smax = sup  # sigma_max at a gamma is at most the one over every gamma: two solves that agree to their accuracy
        numbers.update({"sigma_sup": sup} if sup else {})
        parts.append(f"no gamma makes (45) feasible at sigma = {sg:g}"
                     + (f" (any gamma needs sigma < {sup:.3g})" if sup else ""))  # fmt: skip
        if sup is None and (why := reachability(aug, getattr(ts, "rule_distances", None))):
            parts.append(why)
    else:
        numbers["gamma_min"] = gmin
        lowered = options.gamma1 is None and not math.isclose(g1, default_gamma1(ts, options), rel_tol=1e-12)
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
            cand = round_gamma(max(gmin * f, g1 * 1.01), gamma_size(ts))
            if try_design(attempt, ts, options, refused, gamma=cand) is not None:
                fixes.append(f"raise gamma to >= {cand:g}")
                numbers["gamma_checked"] = cand
                break
    if smax is None:
        parts.append(f"no sigma > 0 makes it feasible at gamma = {g:g}")
    else:
        numbers["sigma_max"] = smax
        parts.append(f"the largest sigma for which it is feasible with gamma = {g:g} is {smax:.3g}")
        for f in (0.95, 0.8, 0.6, 0.4, 0.2, 0.1):
            cand = nice_floor(smax * f)
            if try_design(attempt, ts, options, refused, sigma=cand) is not None:
                fixes.append(f"lower sigma to <= {cand:g}")
                numbers["sigma_checked"] = cand
                break
    if not fixes and smax is not None and (binds := _kappa_binds(aug, params, smax, solver)) is not None:
        s_at, k_at = binds
        numbers.update(sigma_kappa_binds=s_at, kappa_needed=k_at)
        parts.append(f"at sigma = {s_at:g}, below that bound, (45) is infeasible with cond(X') <= {KAPPA:g} and feasible "
                     f"with cond(X') <= {k_at:g}: there the bound kappa binds (a state measured in units far from its "
                     "range needs a large one; --kappa sets it, and the design searches it only at the sigma it is "
                     "given, e.g. --sigma)")  # fmt: skip
    checked = "each checked: it gives" if len(fixes) > 1 else "checked: it gives"
    advice = (
        (" or ".join(fixes) + f" ({checked} a certified design)")
        if fixes
        else "no value tried gives a certified design: see `fte design PLANT --explore` for the feasible frontier"
    )
    return InfeasibleDesignError(
        Refusal(
            Refused.LMI,
            f"LMI (45) is infeasible: {'; '.join(parts)}",
            lmi="45",
            numbers=numbers,
            advice=advice,
            checked=bool(fixes),
            tried=first_of_each_kind(refused or []),
        )
    )


def _kappa_binds(aug, params: dict, smax: float, solver: str) -> tuple[float, float] | None:
    """``(sigma, kappa)`` where the bound on cond(X') is what makes (45) infeasible below ``smax``: at 0.8 x it,
    infeasible under the default bound and feasible under ``kappa``, the smallest of the ladder that is (step 3's
    own search, :func:`~fte_casadi.design._pipeline.step3`, which the parameter search's trials leave out); None
    where a kappa was given, where the default bound is not what binds, or where a solve fails."""
    if "kappa" in params:
        return None
    from .._pipeline import on_ladder

    sg = nice_floor(0.8 * smax)

    def feasible(kappa: float) -> bool | None:
        try:
            step3(aug, dict(params, sigma=sg, kappa=kappa), solver)
        except InfeasibleDesignError:
            return None
        return True

    try:
        if feasible(KAPPA) or (found := on_ladder(feasible)) is None:
            return None
    except SolverFailedError:
        return None
    return sg, found[0]


def explain_46(attempt: Attempt, ts, options: DesignOptions, aug, params: dict, exc: InfeasibleDesignError,
               refused: list | None = None) -> InfeasibleDesignError:  # fmt: skip
    """The error for an infeasible (46) at alpha = 0 (``exc``'s refusal): a larger sigma (within what (45)
    allows) that works."""
    g, sg = params["gamma"], params["sigma"]
    smax, _ = sigma_max(aug, g, params["gamma1"], options.solver)
    fix = None
    if smax is not None and smax > sg:
        for f in (0.2, 0.4, 0.6, 0.8, 0.95):
            cand = nice_floor(sg + f * (smax - sg))
            if cand > sg and try_design(attempt, ts, options, refused, sigma=cand) is not None:
                fix = cand
                break
    refusal = exc.refusal
    numbers = dict(refusal.numbers, sigma=sg, gamma=g, **({"sigma_max": smax} if smax else {}),
                   **({"sigma_checked": fix} if fix else {}))  # fmt: skip
    detail = (f"The -sigma I block of (46) must dominate the coupling of the observer with the loop; (45) allows sigma "
              f"up to {smax:.3g} at gamma = {g:g}" if smax else "")  # fmt: skip
    advice = (
        f"Raise sigma to {fix:g} (checked: it gives a certified design)"
        if fix
        else "No larger sigma tried gives a certified design: see `fte design PLANT --explore`"
    )
    return InfeasibleDesignError(
        dataclasses.replace(
            refusal,
            numbers=numbers,
            detail=detail,
            advice=advice,
            checked=fix is not None,
            tried=first_of_each_kind(refused or []),
        )
    )
