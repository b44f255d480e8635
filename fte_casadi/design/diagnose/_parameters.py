"""The parameter search: what a design tries when the record it was given does not give a certified design.

Every trial is the given :class:`~fte_casadi.design._options.DesignOptions` changed with
:meth:`~fte_casadi.design._options.DesignOptions.replace` (another sigma, another gamma) and designed again by
``attempt`` (one attempt of :func:`fte_casadi.design.design`, passed in so that this module does not import
the one that calls it). A trial's settings are resolved afresh, so what the plant's defaults gave stays a
default in every trial. A trial refused is kept as a :class:`Trial`: the change and the error, read by field.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass

from ..._progress import stage
from ..._rounding import nice_floor
from ..._text import shorten
from ...errors import FteError, InfeasibleDesignError
from .._options import DesignOptions, gamma_size, round_gamma
from .._record import Design
from ..core._diagnose import gamma_min, sigma_max

__all__ = ["choose", "try_design", "Trial", "first_of_each_kind"]

#: one attempt of the design: ``attempt(ts, options) -> Design``
Attempt = Callable[..., Design]

#: fractions of the largest feasible sigma tried, in order, when the tool chooses sigma itself
SIGMA_TRIALS = (0.8, 0.6, 0.4, 0.2, 0.1, 0.05)
#: multiples of the smallest feasible gamma tried when the tool chooses gamma itself
GAMMA_TRIALS = (1.25, 1.6, 2.5, 4.0, 10.0)


@dataclass(frozen=True)
class Trial:
    """A value tried and refused: the change of the options (``{"sigma": 0.4}``) and the error that refused it
    (None: the design was made but not certified)."""

    change: dict
    error: FteError | None
    #: ``(id(ts), id(options))`` of the attempt: the same change asked again of the same model and options is not
    #: made again (:func:`try_design`; the parameter search and the refusal's explanation try some of the same)
    of: tuple = ()

    @property
    def lmi(self) -> str | None:
        """The registered LMI that refused the trial, where one did (``"46"``: step 3's (45) held)."""
        return getattr(self.error, "lmi", None)

    @property
    def kind(self) -> tuple:
        """What refused it, as data: the error's class and, for a refusal, its kind and LMI."""
        if isinstance(self.error, InfeasibleDesignError):
            return (type(self.error), self.error.refusal.kind, self.error.refusal.lmi)
        return (type(self.error), None, self.lmi)

    @property
    def message(self) -> str:
        return " ".join(str(self.error).split()) if self.error is not None else "not certified"


def try_design(
    attempt: Attempt, ts, options: DesignOptions, refused: list | None = None, **change
) -> Design | None:
    """The whole design with ``options`` changed by ``change`` (without diagnosis unless ``change`` asks for it,
    a certificate required), or None when it does not give a certified design (then its :class:`Trial` is
    appended to ``refused``; a change already refused there for the same ``ts`` and ``options`` is not tried again:
    a design is a function of them)."""
    of = (id(ts), id(options))
    if refused is not None and any(t.of == of and t.change == change for t in refused):
        return None
    try:
        d = attempt(ts, options.replace(**{"diagnose": False, "allow_uncertified": False, **change}))
    except FteError as exc:
        if refused is not None:
            refused.append(Trial(change, exc, of))
        return None
    if not d.certified and refused is not None:
        refused.append(Trial(change, None, of))
    return d if d.certified else None


def first_of_each_kind(refused: list[Trial], count: int = 2) -> tuple:
    """What stopped the values tried, for a refusal's ``tried``: the first trial of each kind (:attr:`Trial.kind`),
    at most ``count`` of them, as ``(change, message)``: a bound can be right and the design still fail at it for
    another reason (e.g. the sample time)."""
    seen, out = set(), []
    for t in refused:
        if t.kind not in seen:
            seen.add(t.kind)
            out.append((t.change, t.message))
    return tuple(out[:count])


def choose(attempt: Attempt, ts, options: DesignOptions, aug, params: dict, generic, lmi: str, exc,
           refused: list | None = None) -> Design | None:  # fmt: skip
    """Parameters the tool finds itself: when sigma and/or gamma came from the generic defaults (neither the
    user nor the plant set them) and the design fails at them, the feasibility bounds say where to look:
    sigma below the largest sigma (45) allows, else gamma above the smallest one it allows (rounded to two
    digits in the size of the outputs and unknown inputs, :func:`~.._options.gamma_size`). The first value
    tried that gives a certified design is taken, and the document's ``params_chosen`` says what was chosen
    and why. None when nothing was generic or nothing tried works. ``lmi``: the LMI that failed, "45" or "46"."""
    if not generic:
        return None
    solver = options.solver
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    gs = gamma_size(ts)  # gammas rounded in the size of y and d: the choice does not depend on their units

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
                    ({"sigma": sc, "gamma": round_gamma(max(gm * gf, g1 * 1.01), gs)}, why)
                    for gf in (1.25, 2.5)
                )
        if "gamma" in generic:
            gmin, _ = gamma_min(aug, sg, g1, solver)
            if gmin is not None:
                why = f"the smallest gamma for which (45) is feasible at sigma = {sg:g}, gamma1 = {g1:g} is {gmin:.3g}"
                yield from (({"gamma": round_gamma(max(gmin * f, g1 * 1.01), gs)}, why) for f in GAMMA_TRIALS)

    for k, (change, why) in enumerate(trials(), 1):
        tried = ", ".join(f"{n} = {v:g}" for n, v in change.items())
        with stage(f"parameter search, trial {k}: {tried} (LMI ({lmi}) refused the defaults)"):
            d = try_design(attempt, ts, options, refused, **change)
        if d is not None:
            first = shorten(exc, 200)
            chosen = {k: {"value": v, "why": f"the generic default {params[k]:g} failed ({first}); {why}; "
                          f"{k} = {v:g} is the first value tried that gives a certified design"}
                      for k, v in change.items()}  # fmt: skip
            notes = [f"{k} = {c['value']:g} chosen by the tool: {c['why']}" for k, c in chosen.items()]
            return dataclasses.replace(d, params_chosen=chosen, status=notes + list(d.status))
    return None
