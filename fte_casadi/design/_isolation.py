"""How far each fault's estimate moves while only another fault is present: the observer's cross-talk.

In a sensor-fault window the loop without tolerant control already uses the observer's ``xhat``, from which
the observer removes the sensor fault; tolerant control adds only ``Kf fhat``, whose sensor columns are zero
(``Kf = -pinv(B) Bf``), so what it feeds into the plant there is the actuator-fault estimate's cross-talk from
the sensor fault. :func:`crosstalk` measures that cross-talk on the design itself, noise-free: after a unit
step of fault q alone, the estimate error of the augmented observer is ``e(t) = exp(R_i t) T e_q`` (the step
moves the state, not z; ``xbarhat = z + H y`` takes ``H Cbar e_q`` of it at once), so that

    fhat_q(t) = 1 - [exp(R_i t) T e_q]_q,     fhat_j(t) = -[exp(R_i t) T e_q]_j   (j != q),

and ``kappa[j, q] = sup_t |fhat_j(t)| / |fhat_q(t)|``, the largest over the rules (each frozen) and over both of
the step's edges (at its end ``fhat_q = 1 - `` the start's, ``fhat_j`` the start's negated), is how much of fault
j's estimate fault q's estimate can explain at any moment. (Over the start alone it was no bound at the end: fault
q's estimate falls at once while fault j's cross-talk decays more slowly, and the gate then compensated that
cross-talk after every sensor-fault window, docs/design.md.) The step's gate
(:func:`fte_casadi.step.accommodation_gate`, rule ``"explain"``) compensates fault j only while
``|fhat_j| >= threshold_j + sum_q kappa[j, q] |fhat_q|``: detected, and more than the other faults' estimates
can explain. A fault whose step is a sum of steps of one sign (a ramp, a stuck sensor drifting away) gives a
weighted mean of such ratios, below the same bound. Noise, the unknown inputs and the blending of the rules
are not in it: the gate's effect is measured by the Monte Carlo, not certified (docs/design.md).
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

__all__: list[str] = []  # internal: docs/design.md describes it

#: a ratio beyond this is reported as this (fault q's estimate explains any size of fault j's: the pair is not
#: told apart by this observer)
KAPPA_CAP = 1e3
#: points of the logarithmic time grid, from 1e-6 of the fastest mode's time constant to 30 of the slowest's
POINTS = 400
#: the largest ratio found (on the grid, refined around its peak) is rounded up by this fraction: a bound
REFINE_MARGIN = 0.01


class _StepResponse:
    """``(exp(R t) - I) e0`` for many t, without the cancellation of ``1 - exp(..)`` at small t (the ratio's
    limit at t -> 0 is often its largest): expm1 of the eigenvalues, or the phi-function by a block expm where
    the eigenvectors are ill-conditioned."""

    def __init__(self, R: np.ndarray):
        self.R = R
        w, V = np.linalg.eig(R)
        self.w, self.V, self.Vi = w, V, None
        if np.linalg.cond(V) < 1e8:
            self.Vi = np.linalg.inv(V)

    def delta(self, e0: np.ndarray, times: np.ndarray) -> np.ndarray:
        if self.Vi is not None:
            return np.real(
                (self.V[None, :, :] * np.expm1(np.outer(times, self.w))[:, None, :]) @ (self.Vi @ e0)
            )
        return np.array([_phi_step(self.R, t) @ e0 for t in times])

    def ratios(
        self, e0: np.ndarray, own: int, other: int, times: np.ndarray, end: bool = False
    ) -> np.ndarray:
        """``|fhat_other(t)| / |fhat_own(t)|`` after a unit step of the fault at ``own``; ``end``: after the end of
        that fault, held long enough for its estimate to reach it (``fhat_own = 1 - `` the start's, ``fhat_other``
        the start's negated)."""
        D = self.delta(e0, times)
        f_own = (1.0 - e0[own]) - D[:, own]
        f_own = np.abs(1.0 - f_own if end else f_own)
        f_other = np.abs(e0[other] + D[:, other])
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(
                f_own > 0, f_other / np.where(f_own > 0, f_own, 1.0), np.where(f_other > 0, np.inf, 0.0)
            )


def _phi_step(R: np.ndarray, t: float) -> np.ndarray:
    """``exp(R t) - I`` accurately for small ``t``: ``R t phi1(R t)`` from ``expm([[R t, I], [0, 0]])``."""
    k = R.shape[0]
    M = np.zeros((2 * k, 2 * k))
    M[:k, :k] = R * t
    M[:k, k:] = np.eye(k)
    phi = sla.expm(M)[:k, k:]
    return (R * t) @ phi


def _decaying(R):
    """Per rule whose observer decays: its logarithmic time grid, from 1e-6 of its fastest mode's time constant to
    30 of its slowest's, its step responses (:class:`_StepResponse`) and its slowest decay rate."""
    for Ri in R:
        Ri = np.asarray(Ri, dtype=float)
        lam = np.linalg.eigvals(Ri)
        if np.all(lam.real < 0):
            slow, fast = float(np.min(-lam.real)), float(np.max(np.abs(lam)))
            yield np.geomspace(1e-6 / fast, 30.0 / slow, POINTS), _StepResponse(Ri), slow


def crosstalk(R, T, n: int, lf: int, end: bool = True) -> np.ndarray:
    """``kappa`` (lf x lf, zero diagonal): the largest ratio ``|fhat_j(t)| / |fhat_q(t)|`` after a unit step of
    fault q alone, over the rules ``R`` (each ``T Abar_i - L1_i Cbar``), a logarithmic time grid and both of the
    step's edges (its start, and its end once the estimate has reached it: ``fhat_q = 1 - own(t)``, ``fhat_j`` the
    start's negated); see the module docstring. At its end, fault q's estimate falls while the cross-talk it
    caused is still decaying, so the end's ratio is often the larger, and often beyond the cap: the gate then
    relies on :func:`crosstalk_held`. Capped at :data:`KAPPA_CAP`; zeros for a rule whose observer does not
    decay. ``end=False``: the start alone (what documents written before 2026-11-29 hold)."""
    T = np.asarray(T, dtype=float)
    kappa = np.zeros((lf, lf))
    if lf < 2:
        return kappa
    for ts, steps, _ in _decaying(R):
        for q in range(lf):
            e0 = T[:, n + lf + q]
            for j in range(lf):
                if j == q:
                    continue
                for edge in (False, True) if end else (False,):
                    ratio = steps.ratios(e0, n + lf + q, n + lf + j, ts, edge)
                    k = int(np.argmax(ratio))
                    # the grid's largest, refined between its neighbours, then rounded up by REFINE_MARGIN
                    fine = np.geomspace(ts[max(k - 1, 0)], ts[min(k + 1, len(ts) - 1)], 65)
                    top = max(
                        float(ratio[k]), float(np.max(steps.ratios(e0, n + lf + q, n + lf + j, fine, edge)))
                    )
                    kappa[j, q] = max(kappa[j, q], min(top * (1 + REFINE_MARGIN), KAPPA_CAP))
    return kappa


def overshoot(R, T, n: int, lf: int) -> tuple[np.ndarray, float]:
    """``(ov, tau)``: how far each fault's own estimate swings past a unit step of that fault, weighted so that a
    memory decaying with time constant ``tau`` covers it: ``ov_j = sup_t max(0, fhat_j(t) - 1) exp(t / tau)``
    over the rules, ``tau = 2 / (slowest decay rate over the rules)``. At a fault's end the estimate swings the
    other way by as much (the error dynamics are linear), so ``ov_j`` times the estimate's recent extreme of one
    sign, decayed, bounds what its swing to the other sign can be after that fault ends."""
    T = np.asarray(T, dtype=float)
    ov = np.zeros(lf)
    rules = list(_decaying(R))
    if not rules:
        return ov, float("inf")
    tau = 2.0 / min(slow for _, _, slow in rules)
    for times, steps, _ in rules:
        for j in range(lf):
            e0 = T[:, n + lf + j]
            own = n + lf + j
            fh = (1.0 - e0[own]) - steps.delta(e0, times)[:, own]
            ov[j] = max(
                ov[j], float(np.max(np.maximum(fh - 1.0, 0.0) * np.exp(times / tau))) * (1 + REFINE_MARGIN)
            )
    return ov, tau


def crosstalk_held(R, T, n: int, lf: int, tau: float) -> np.ndarray:
    """``kappa`` (lf x lf, zero diagonal) of the gate that weighs each other fault's *held* estimate: the smallest
    ``k`` with ``|fhat_j(t)| <= k M_q(t)`` for fault q alone, ``M_q`` the largest ``|fhat_q|`` so far, decaying
    by ``exp(-dt / tau)`` (what the step's memories hold, :func:`overshoot`'s ``tau``). Both of a step's edges:

    - its start, ``fhat_q = own(t)``, ``M_q`` the decayed running largest of ``|own|``;
    - its end (the fault held long enough for ``fhat_q = 1``): ``fhat_q = 1 - own(t)``, ``fhat_j`` the
      start's negated, and ``M_q`` at least ``exp(-t / tau)``, the 1 held before the end.

    :func:`crosstalk` divides by ``|fhat_q(t)|`` itself, which a non-minimum-phase estimate (one that starts the
    wrong way) passes through zero while ``fhat_j`` is not: its ratio is unbounded there (capped at
    :data:`KAPPA_CAP`), and the gate then blocks fault j while fault q's estimate is anything but tiny. The held
    estimate does not pass through zero. Over the rules (each frozen); capped at :data:`KAPPA_CAP`."""
    T = np.asarray(T, dtype=float)
    kappa = np.zeros((lf, lf))
    if lf < 2:
        return kappa
    for grid, steps, _ in _decaying(R):
        times = np.geomspace(grid[0], grid[-1], HELD_POINTS)
        for q in range(lf):
            e0 = T[:, n + lf + q]
            D = steps.delta(e0, times)
            own = (1.0 - e0[n + lf + q]) - D[:, n + lf + q]
            held_start = _held(np.abs(own), times, tau)
            held_end = np.maximum(_held(np.abs(1.0 - own), times, tau), np.exp(-times / tau))
            for j in range(lf):
                if j == q:
                    continue
                ct = np.abs(e0[n + lf + j] + D[:, n + lf + j])
                with np.errstate(divide="ignore", invalid="ignore"):
                    r = np.where(held_start > 0, ct / np.where(held_start > 0, held_start, 1.0),
                                 np.where(ct > 0, np.inf, 0.0))  # fmt: skip
                top = max(float(np.max(r)), float(np.max(ct / held_end)))
                kappa[j, q] = max(kappa[j, q], min(top * (1 + REFINE_MARGIN), KAPPA_CAP))
    return kappa


#: points of :func:`crosstalk_held`'s logarithmic time grid (no refinement: its held denominators do not dip)
HELD_POINTS = 4000


def _held(x: np.ndarray, times: np.ndarray, tau: float) -> np.ndarray:
    """At each of ``times``, the largest of ``x`` so far, each earlier value decayed by ``exp(-(t - t_k) / tau)``:
    ``exp(-t / tau)`` times the running largest of ``x_k exp(t_k / tau)`` (``t / tau`` is at most 15 on
    :func:`_decaying`'s grids, 30 of a rule's slowest time constant against ``tau``, twice the slowest of all)."""
    grow = np.exp(times / tau)
    return np.maximum.accumulate(x * grow) / grow
