"""The masks of the metrics over the samples: the fault windows (whole and settled), the start-up allowance and
the allowance after a window's end (:func:`allowances`), each window's onset and the span after it (no fault in the
plant there); rows of :class:`Masks`, read by :mod:`._reduce` (streamed) and :mod:`._metrics` (from the arrays)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

__all__ = []  # public: docs/api.md

#: fraction of each fault window left out of ``fault_rel_rms_error_settled`` (only there)
SETTLE_FRACTION = 0.2
#: the start-up allowance and the allowance after a window: this many of the observer's slowest time constant
TAU_MULTIPLE = 3.0
#: ... but at most this share of the shortest fault window (and of the horizon)
WINDOW_SHARE = 0.25


def _mask(t: np.ndarray, windows, settle: float = 0.0) -> np.ndarray:
    m = np.zeros(t.shape, bool)
    for a, b in windows:
        m |= (t >= a + settle * (b - a)) & (t < b)
    return m


@dataclass(frozen=True)
class Allowances:
    """The start-up allowance ``transient`` and the allowance after a window's end ``settle_after``
    (both in the plant's time unit), derived from the observer's slowest time constant ``tau``."""

    transient: float
    settle_after: float
    tau: float
    capped: bool
    why: str


def allowances(design, scenario) -> Allowances:
    """``TAU_MULTIPLE`` x the observer's slowest time constant (``1 / |max Re eig R_i|``); the start-up
    allowance at most half the time before the first fault window (and ``WINDOW_SHARE`` of the horizon),
    the allowance after a window at most ``WINDOW_SHARE`` of the shortest window."""
    re = float(design.checks.get("R_max_real_eig", -math.inf) or -math.inf)
    tau = math.inf if not (math.isfinite(re) and re < 0) else 1.0 / -re
    want = TAU_MULTIPLE * tau
    first = min((float(fp.start) for fp in scenario.faults), default=float(scenario.T))
    cap_t = min(0.5 * first, WINDOW_SHARE * float(scenario.T)) if first > 0 else 0.0
    lengths = [float(fp.stop) - float(fp.start) for fp in scenario.faults]
    cap_a = WINDOW_SHARE * min(lengths) if lengths else want
    transient, after = min(want, cap_t), min(want, cap_a)
    why = (
        f"{TAU_MULTIPLE:g} x the observer's slowest time constant ({TAU_MULTIPLE:g} x {tau:.4g} = {want:.4g})"
    )
    capped = transient < want or after < want
    if transient < want:
        why += f"; the start-up allowance capped at {transient:.4g} (half the time before the first fault)"
    if after < want:
        why += (
            f"; the allowance after a window capped at {after:.4g} ({WINDOW_SHARE:g} of the shortest window)"
        )
    return Allowances(transient, after, tau, capped, why)


@dataclass(frozen=True)
class Masks:
    """Per-sample masks, rows of ``M`` (nmask, samples), in this order: ``after`` (t >= transient);
    per fault its whole windows; per fault its settled windows (each minus its first 20 %); the union of
    all windows; per window all of it; per window its settled part; per fault ``outside`` (after the
    transient, outside its windows and not within ``settle_after`` of one's end); per fault its samples
    outside before the transient and within ``settle_after`` of a window's end; per window its onset; per window
    the span after it (:func:`after_span`)."""

    M: np.ndarray
    fault_of_window: tuple[int, ...]
    windows: tuple[tuple[str, float, float], ...]
    lf: int
    transient: float
    settle_after: float

    @property
    def nw(self) -> int:
        return len(self.windows)

    def row(self, kind: str, k: int = 0) -> int:
        lf, nw = self.lf, self.nw
        base = {"after": 0, "fault": 1, "fault_settled": 1 + lf, "union": 1 + 2 * lf, "window": 2 + 2 * lf,
                "window_settled": 2 + 2 * lf + nw, "outside": 2 + 2 * lf + 2 * nw,
                "startup_outside": 2 + 3 * lf + 2 * nw, "lag_outside": 2 + 4 * lf + 2 * nw,
                "onset": 2 + 5 * lf + 2 * nw, "after_window": 2 + 5 * lf + 3 * nw}[kind]  # fmt: skip
        return base + k


def outside_mask(t: np.ndarray, wins, transient: float, settle_after: float) -> np.ndarray:
    """After ``transient``, outside ``wins`` and not within ``settle_after`` of a window's end."""
    lag = _mask(t, [(b, b + settle_after) for _, b in wins]) if settle_after > 0 else np.zeros(t.shape, bool)
    return (t >= transient) & ~_mask(t, wins) & ~lag


def allowance_masks(
    t: np.ndarray, wins, transient: float, settle_after: float
) -> tuple[np.ndarray, np.ndarray]:
    """The samples outside ``wins`` that the allowances leave out: before ``transient``, and (after it)
    within ``settle_after`` of a window's end."""
    lag = _mask(t, [(b, b + settle_after) for _, b in wins]) if settle_after > 0 else np.zeros(t.shape, bool)
    out = ~_mask(t, wins)
    return out & (t < transient), out & (t >= transient) & lag


def onset_mask(t: np.ndarray, a: float) -> np.ndarray:
    """The first sample of a window starting at ``a`` (``t_k >= a``)."""
    m = np.zeros(t.shape, bool)
    k = np.flatnonzero(t >= a)
    if len(k):
        m[k[0]] = True
    return m


def masks(t: np.ndarray, scenario, fault_names, allow: Allowances) -> Masks:
    names = list(fault_names)
    wins = [list(scenario.windows(nm)) for nm in names]
    prof = [(fp.fault, float(fp.start), float(fp.stop)) for fp in scenario.faults]
    rows = [t >= allow.transient]
    rows += [_mask(t, wins[j]) for j in range(len(names))]
    rows += [_mask(t, wins[j], SETTLE_FRACTION) for j in range(len(names))]
    rows.append(_mask(t, [w for ws in wins for w in ws]))
    rows += [_mask(t, [(a, b)]) for _, a, b in prof]
    rows += [_mask(t, [(a, b)], SETTLE_FRACTION) for _, a, b in prof]
    rows += [outside_mask(t, wins[j], allow.transient, allow.settle_after) for j in range(len(names))]
    parts = [allowance_masks(t, wins[j], allow.transient, allow.settle_after) for j in range(len(names))]
    rows += [p[0] for p in parts] + [p[1] for p in parts]
    rows += [onset_mask(t, a) for _, a, _ in prof]
    rows += [after_mask(t, prof, w, float(scenario.T)) for w in range(len(prof))]
    M = np.array(rows, dtype=float).reshape(len(rows), len(t))
    return Masks(M, tuple(names.index(f) for f, _, _ in prof), tuple(prof), len(names), allow.transient,
                 allow.settle_after)  # fmt: skip


def after_span(windows, w: int, horizon: float = math.inf) -> tuple[float, float]:
    """The span after window ``w`` of ``windows`` (``(fault, start, stop)`` each): from its end to the start of
    the next fault window of any fault, or to ``horizon``; empty (``(b, b)``) where another window holds its end.
    No fault is in the plant there."""
    _, _, b = windows[w]
    if any(a < b < e for _, a, e in windows):  # overlapping windows: no fault-free span follows this one
        return float(b), float(b)
    later = [s for _, s, _ in windows if s >= b]
    return float(b), float(min(later)) if later else float(horizon)


def after_mask(t: np.ndarray, windows, w: int, horizon: float = math.inf) -> np.ndarray:
    """The samples of :func:`after_span` of window ``w``."""
    b, end = after_span(windows, w, horizon)
    return (t >= b) & (t < end)


def release_mask(t: np.ndarray, mk: Masks, w: int) -> np.ndarray:
    """The samples after window ``w``'s end up to the start of the next fault window of any fault (or the
    horizon): where the estimate falls back to zero undisturbed."""
    _, _, b = mk.windows[w]
    later = [s for _, s, _ in mk.windows if s >= b]
    end = min(later) if later else math.inf
    return (t >= b) & (t < end)
