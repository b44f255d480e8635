"""The observer's decay rate in step 5 (conditioned variant): the largest feasible one, and the one the
sample time allows.

``prob`` is step 5's problem (:class:`fte_casadi.design.core._step5._Step5`): ``prob.feasible(alpha)`` decides
whether (46) with the normalisation is feasible at ``alpha``, ``prob.design(alpha)`` returns the centred design
there (or None)."""

from __future__ import annotations

import numpy as np

from ..._rounding import nice_floor
from ...errors import InfeasibleDesignError, Refused

__all__ = ["alpha_max"]  # public: docs/api.md

#: the default decay rate keeps ts_max >= TS_FACTOR * sample_time
TS_FACTOR = 2.0
#: relative precision of the bisection on alpha
ALPHA_RTOL = 0.1


def alpha_max(prob, start: float, rtol: float = ALPHA_RTOL) -> tuple[float, float]:
    """``(lo, hi)``: (46) with ``I <= Pt <= kappa I`` is feasible at ``lo`` and not at ``hi``
    (``hi / lo <= 1 + rtol``); bracketing by factors of 4 from ``start``, then bisection in log
    scale, every decision by ``prob.feasible``. The trials depend on the answers only, not
    on the points found. ``hi`` is ``inf`` when every trial up to ``start * 4^12`` was feasible;
    ``lo = 0`` when no trial down to ``1e-6 start`` was."""
    lo, a = 0.0, start
    for _ in range(12):
        if prob.feasible(a):
            lo, a = a, 4 * a
        else:
            break
    else:
        return lo, float("inf")
    hi = a
    if lo == 0.0:
        while hi > 1e-6 * start:
            a = hi / 8
            if prob.feasible(a):
                lo = a
                break
            hi = a
        else:
            return 0.0, hi
    while hi / lo > 1 + rtol:
        mid = float(np.sqrt(lo * hi))
        if prob.feasible(mid):
            lo = mid
        else:
            hi = mid
    return lo, hi


#: decay rates tried below the default when the sample time asks for it, as fractions of it
CAP_GRID = (0.875, 0.75, 0.625, 0.5, 0.375, 0.25, 0.125, 0.0)


def cap_for_sample_time(prob, a: float, pt: dict, why: str, sample_time: float):
    """The largest alpha of ``CAP_GRID x a`` whose centred design runs at ``sample_time`` with margin.

    The measure is ``ts_cert`` (:func:`~fte_casadi.design.core._certify.lyapunov_ts_max`): the largest Ts for
    which Pbar proves the blended discrete step stable (not monotone in alpha: the centred point
    moves with it, hence a scan, not a bisection). The target is ``TS_FACTOR * sample_time``; when no
    alpha tried reaches it but some reach ``sample_time``, the largest such alpha is taken (stable at
    the sample time, with less margin; said so). When none does, no design of this formulation was
    found that runs at that rate, and the error names the fastest sample time found and what limits it.
    """
    target = TS_FACTOR * sample_time

    def lowered(al, p, how):
        if al == a:  # no lower rate reached the margin: the rate stays, stable at the sample time with less
            return al, p, why + (f"; kept: the discrete step is proven stable for Ts < {p['ts_cert']:.3g} ({how} the "
                                 f"sample time {sample_time:g}; no lower rate tried reaches {TS_FACTOR:g} x it)")  # fmt: skip
        return al, p, why + (f"; lowered to {al:.4g} so that the discrete step is proven stable for Ts < "
                             f"{p['ts_cert']:.3g} ({how} the sample time {sample_time:g})")  # fmt: skip

    tried = []  # designed in the grid's order, only as far as the first that reaches the target
    for k, al in enumerate([a] + [f * a for f in CAP_GRID]):
        p = pt if k == 0 else prob.design(al)
        if p is not None:
            tried.append((al, p))
            if p["ts_cert"] >= target:
                return lowered(al, p, f">= {TS_FACTOR:g} x")
    for al, p in tried:  # none reached the target: every alpha of the grid was designed
        if p["ts_cert"] >= sample_time:
            return lowered(al, p, "above")
    al, best = max(tried, key=lambda t: t[1]["ts_cert"]) if tried else (None, None)
    fastest = 0.0 if best is None else best["ts_cert"]
    limit = ""
    if best is not None:
        lam = max((lam for Ri in best["R"] for lam in np.linalg.eigvals(Ri)), key=abs)
        limit = (
            f" (at alpha = {al:.3g}); what limits it is the observer's fastest mode, |lambda| = {abs(lam):.3g} "
            "(Ts |lambda| must stay well below 2), set by the gains L_i1 that (46) needs to dominate the loop's "
            "coupling"
        )
    # what a shorter sample time buys: per decay rate tried, the sample time its design is proven stable below
    table = "; ".join(
        f"alpha {al:.3g}: Ts < {p['ts_cert']:.2g}" for al, p in sorted(tried, key=lambda t: -t[0])
    )
    raise InfeasibleDesignError(
        f"no certified design runs at the sample time {sample_time:g}: over the observer decay rates tried "
        f"(0 to {a:.3g}) the discrete step z+ = z + Ts (...) is proven stable at best for Ts < {fastest:.3g}{limit}. "
        f"Run the observer at a sample time <= {nice_floor(fastest):g} (--sample-time, and the scenario's dt), "
        f"where it decays at {al:.3g}; a faster observer needs a shorter one ({table}), "
        "or change sigma/gamma (`fte design PLANT --explore` shows ts_max per row)",
        kind=Refused.SAMPLE_TIME,
        lmi="46",
        numbers={"sample_time": sample_time, "ts_max": fastest},
    )


#: the default closed loop's decay rate, as a multiple of the open loop's slowest one (a stable open loop)
LOOP_SPEEDUP = 2.0
#: where that rate is infeasible at the design's parameters, at least this multiple
LOOP_AT_LEAST = 1.25


def loop_decay_target(aug) -> tuple[tuple[float, float], str]:
    """``((asked, at_least), why)``: the decay rates asked of the closed loops ``A_i + B_i K`` by default.

    A control engineer expects the loop to be faster than the plant left alone, with a gain that is not
    negligible against it. For a stable open loop (every ``A_i`` Hurwitz), :data:`LOOP_SPEEDUP` times its slowest
    decay rate ``min_i -max Re eig(A_i)`` is asked, and at least :data:`LOOP_AT_LEAST` times it where that is
    infeasible; for an open loop that diverges, the rate at which it grows (the mirror image a smallest
    stabilising gain gives), or its slowest decaying mode where that is faster; for a marginal one (an
    integrator), its slowest decaying mode. Both zero (no requirement) only for a plant without a decaying mode
    (every eigenvalue on the imaginary axis)."""
    n = aug.n
    eigs = [np.linalg.eigvals(A[:n, :n]) for A in aug.Abar]
    rho = max(float(np.max(np.abs(e))) for e in eigs) if n else 0.0
    decay_ol = min(-float(np.max(e.real)) for e in eigs) if n else 0.0
    tiny = 1e-9 * max(rho, 1e-300)
    slow = [-float(x.real) for e in eigs for x in e if -x.real > tiny]
    slowest = min(slow) if slow else 0.0
    if decay_ol > tiny:
        return (LOOP_SPEEDUP * decay_ol, LOOP_AT_LEAST * decay_ol), (
            f"asked {LOOP_SPEEDUP:g} x the open loop's slowest decay rate {decay_ol:.4g} (the default: a loop faster "
            "than the plant left alone)"
        )
    if decay_ol < -tiny:
        b = max(-decay_ol, slowest)
        return (b, b), (
            f"the open loop diverges at the rate {-decay_ol:.4g}: asked to decay at least at {b:.4g} (the default)"
        )
    return (slowest, slowest), (
        f"the open loop is marginally stable: asked to decay at least as fast as its slowest decaying mode "
        f"({slowest:.4g}, the default)"
        if slowest > 0
        else "the open loop has no decaying mode: no rate asked"
    )
