"""What could make a certified design fit its scenario, tried rather than guessed.

A design can be certified and still useless where it runs: an observer whose slowest time constant is longer
than the scenario's fault windows (its estimates cannot settle inside them), or whose decay rate was lowered
to 0 to certify the discrete step. :func:`remedies` designs the plant again with each change that can give a
faster certified observer, and says what each gave:

- a larger ``kappa`` (the bound on cond(Pbar)): the decay rate is chosen as a fraction of the largest one
  (46) allows under that bound, and a looser conditioning allows a faster one;
- a shorter sample time, when the rate was lowered to certify the discrete step at the given one.

Every line is the outcome of a whole design (both steps and the certificate); nothing is advised unrun.
"""

from __future__ import annotations

from .._text import shorten
from ..errors import FteError
from ._options import DesignOptions
from ._record import Design
from .core._conditioned import KAPPA

__all__ = []

#: the factors tried on kappa, and on the sample time when the decay rate was lowered for it
KAPPA_FACTORS = (1e2, 1e4)
SAMPLE_TIME_FACTORS = (0.5, 0.25)


def _slowest(d: Design) -> float | None:
    """The observer's slowest time constant ``1 / |max Re eig R_i|`` (None when a mode does not decay)."""
    re = d.checks.get("R_max_real_eig")
    return 1.0 / -re if re is not None and re < 0 else None


def remedies(
    ts, options: DesignOptions, d: Design, scenario, *, settle: float = 3.0, design_fn=None
) -> list[str]:
    """For a design whose observer is too slow for ``scenario``'s shortest fault window (``settle`` time constants
    longer than it) or whose decay rate is 0: each change tried, with what the whole design gave. Empty when
    the design fits or the scenario has no faults. ``design_fn`` (default :func:`fte_casadi.design.design`)."""
    if scenario is None or not scenario.faults:
        return []
    if design_fn is None:
        from ._api import design as design_fn
    shortest = min(float(f.stop) - float(f.start) for f in scenario.faults)
    tau = _slowest(d)
    alpha = float(d.observer.alpha) if d.observer.alpha is not None else None
    if tau is not None and settle * tau <= shortest and alpha != 0.0:
        return []
    kappa = options.kappa or KAPPA
    changes = [{"kappa": kappa * f} for f in KAPPA_FACTORS]
    lowered = d.observer.alpha_before_sample_time is not None  # the sample time bound the rate
    if options.sample_time is not None and (lowered or alpha == 0.0):
        changes += [{"sample_time": options.sample_time * f} for f in SAMPLE_TIME_FACTORS]
    # at the parameters the design ended with (the tool may have chosen them): only the change differs
    base = options.replace(
        **{k: getattr(d.params, k) for k in ("sigma", "gamma", "gamma1", "delta", "epsilon")}
    )
    out = []
    for change in changes:
        what = " ".join(f"--{k.replace('_', '-')} {v:g}" for k, v in change.items())
        try:
            d2 = design_fn(ts, base.replace(diagnose=False, allow_uncertified=False, **change))
        except FteError as exc:
            out.append(f"{what}: refused ({shorten(exc, 160)})")
            continue
        t2 = _slowest(d2)
        if t2 is None:
            out.append(f"{what}: certified, but the observer's slowest mode does not decay")
            continue
        fits = settle * t2 <= shortest and float(d2.observer.alpha) > 0
        flag = " ".join(f"--{k.replace('_', '-')} {v:g}" for k, v in change.items())
        out.append(
            f"{flag}: certified, the observer's slowest time constant {t2:.3g} (was "
            f"{'none' if tau is None else f'{tau:.3g}'}), decay rate {float(d2.observer.alpha):.3g}: "
            + ("fits" if fits else "still too slow for")
            + f" the {shortest:.3g} fault windows"
        )
    return out
