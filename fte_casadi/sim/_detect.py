"""Fault detection on top of the estimates: thresholds from fault-free Monte Carlo at a false-alarm rate.

The residual of fault j is its estimate ``|fhat_j|``. The alarm rule: the alarm state starts off at the
start-up allowance ``transient``; an alarm is raised when ``|fhat_j|`` reaches the threshold and cleared
when it falls below :data:`._reduce.HYSTERESIS` of it. Before ``transient`` there is no alarm.

The thresholds are set from fault-free paths that are not the run's own (:mod:`._calibrate`: paths ``P,
P + 1, ...`` of the run's seed), cut into blocks of about the observer's time constant; each path gives the
maximum of ``|fhat_j|`` in every block after ``transient``. From these block maxima, per fault:

1. **The start-up.** Blocks in the second half of ``[transient, T)`` are the reference (whole blocks only).
   A block before them is part of the start-up when more of its paths exceed the reference's 90 % quantile
   than a 3-sigma binomial count allows; the start-up ends with the last such block (``steady_from``). Each
   start-up block gets its own threshold (set as below from its own maxima, never below the steady one):
   the start-up's decay is judged against itself, not against the noise.
2. **The steady threshold**, from the whole blocks from ``steady_from`` on (pooled): the level a block's
   maximum exceeds with probability ``p = 1 - exp(-r L)`` (``r`` the rate asked, ``L`` the block's length:
   alarms as a Poisson process of rate ``r``). Where the data hold at least :data:`N_EMPIRICAL` expected
   exceedances (``n p``), it is the empirical quantile; otherwise the tail above the ``1 - TAIL_SHARE``
   quantile ``u`` is fitted by a generalised Pareto law (method of moments, ``xi = (1 - m^2 / v) / 2``,
   ``sigma = m (1 - xi)`` of the excesses' mean ``m`` and variance ``v``) and the level extrapolated:
   ``threshold = u + sigma / xi ((p / q)^-xi - 1)``, ``q`` the share above ``u``. The fit is checked against
   the data's own extremes (:func:`tail_check`).
3. **The promise.** The expected number of alarms per path over ``[transient, T)`` is the sum over the
   blocks of ``-ln(1 - P(block maximum >= its threshold))`` (the steady part at its rate per unit time over
   its whole duration); divided by ``T - transient`` it is the false-alarm rate the thresholds deliver. Its
   95 % interval comes from a bootstrap over the calibration paths (Poisson(1) weights per path, seeded by
   the run's seed), each replicate re-estimating every block's exceedance probability at the fixed
   thresholds (counts, or the tail refitted with ``u`` fixed): ``false_alarm_rate_interval``.

The calibration runs ``N_EMPIRICAL / r`` of fault-free time after the start-up allowance when that fits in
``budget`` path-steps, at least :data:`MIN_PATHS` paths; :func:`calibration_paths` says how many.
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass

import numpy as np

from ..errors import ParameterError
from ._reduce import HYSTERESIS

__all__ = ["RULE"]  # public: docs/api.md

#: how a threshold was found, and the document's words for it
EMPIRICAL, TAIL = "empirical", "tail"
METHOD_TEXT = {EMPIRICAL: "empirical quantile", TAIL: "tail fit"}
#: expected exceedances in the calibration data at and above which the threshold is the empirical quantile
N_EMPIRICAL = 25
#: share of the block maxima whose tail is fitted when the threshold is extrapolated (at least TAIL_MIN of them)
TAIL_SHARE = 0.02
TAIL_MIN = 50
#: the steady part's blocks (about one observer time constant each) are merged in runs of this many
STEADY_MERGE = 3
#: calibration paths: at least this many (within the budget), and never fewer than FLOOR_PATHS
MIN_PATHS = 200
FLOOR_PATHS = 16
#: default budget of the calibration, in path-steps of the fault-free loop (each of its two passes)
BUDGET = 2e7
#: bootstrap replicates behind the promised interval, and its confidence
BOOTSTRAP = 400
CONFIDENCE = 0.95
#: a start-up block: its count above the reference's 90 % quantile exceeds the binomial mean by this many sigmas
STARTUP_SIGMAS = 3.0
_REF_QUANTILE = 0.9
#: one false alarm per hour of operation, per time unit of the plant
_PER_HOUR = {"s": 1 / 3600.0, "sec": 1 / 3600.0, "ms": 1 / 3.6e6, "min": 1 / 60.0, "h": 1.0, "hour": 1.0}
RULE = (
    "alarm state off until t = {t0:.4g} (transient); raised when |fhat_j| >= threshold, cleared below {h:g} x "
    "threshold; thresholds from block maxima of |fhat_j| on {n} independent fault-free paths ({hours:.3g} path-"
    "hours after the transient) at {rate:.4g} false alarms per unit time: {how}"
)


def default_rate(time_unit: str | None) -> float:
    """One false alarm per hour of operation, in alarms per unit of the plant's time (``s`` if unknown)."""
    return _PER_HOUR.get((time_unit or "s").strip().lower(), 1 / 3600.0)


def hours_per_unit(time_unit: str | None) -> float:
    """Hours in one unit of the plant's time (``s`` if unknown): one hour holds ``1 / default_rate`` units."""
    return default_rate(time_unit)


def budget() -> float:
    """The calibration's budget in path-steps per pass: :data:`BUDGET`, or the environment's
    ``FTE_CALIBRATION_BUDGET`` (the test suite lowers it; a positive number)."""
    raw = os.environ.get("FTE_CALIBRATION_BUDGET")
    if raw is None:
        return BUDGET
    try:
        v = float(raw)
    except ValueError:
        v = math.nan
    if not (math.isfinite(v) and v > 0):
        raise ParameterError(f"FTE_CALIBRATION_BUDGET must be a positive number of path-steps; got {raw!r}")
    return v


def calibration_paths(rate: float, block: float, nsteps: int, given: int | None = None) -> int:
    """Paths for ``N_EMPIRICAL`` expected false alarms at ``rate`` in every block of length ``block`` (a
    start-up block is judged on its own), at least ``MIN_PATHS``, at most the :func:`budget` in path-steps
    (but at least ``FLOOR_PATHS``); ``given``: that many."""
    if given is not None:
        return int(given)
    want = math.ceil(N_EMPIRICAL / (rate * max(block, 1e-300)))
    cap = max(FLOOR_PATHS, int(budget() // max(nsteps, 1)))
    return int(min(max(want, MIN_PATHS), cap))


@dataclass(frozen=True)
class Group:
    """Block maxima judged against one threshold: ``X`` (paths, blocks) of equal length ``L`` each."""

    X: np.ndarray
    L: float

    def stats(self, u: float, levels) -> np.ndarray:
        """Per path: blocks above ``u``, the sums of their excesses and squared excesses, and the blocks at
        or above each level in ``levels`` (paths, 3 + len(levels))."""
        X = self.X
        above = X > u
        ex = np.where(above, X - u, 0.0)
        cols = [above.sum(1), ex.sum(1), (ex * ex).sum(1)] + [(X >= v).sum(1) for v in levels]
        return np.column_stack(cols).astype(float)


@dataclass(frozen=True)
class Tail:
    """The exceedance probability of a block maximum: empirical, or a generalised Pareto tail above ``u``."""

    kind: str  # EMPIRICAL or TAIL
    u: float
    q: float
    xi: float
    sigma: float

    def exceed(self, x: float, frac_at_x: float) -> float:
        """P(block maximum >= x): ``frac_at_x`` (the data's share) below ``u`` or empirically, else the tail."""
        if self.kind == EMPIRICAL or x <= self.u:
            return frac_at_x
        return gpd_exceed(x, self.u, self.q, self.xi, self.sigma)


def gpd_exceed(x, u, q, xi, sigma):
    """``q (1 + xi (x - u) / sigma)^(-1 / xi)`` (0 beyond the upper end; ``q exp(-(x - u) / sigma)`` at xi = 0)."""
    x, xi, sigma, q = (np.asarray(v, dtype=float) for v in (x, xi, sigma, q))
    z = (x - u) / np.where(sigma > 0, sigma, np.nan)
    small = np.abs(xi) < 1e-9
    base = np.maximum(1.0 + xi * z, 0.0)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        gp = np.where(base > 0, base ** (-1.0 / np.where(small, 1.0, xi)), 0.0)
        out = q * np.where(small, np.exp(-z), gp)
    return np.where(np.isfinite(out), out, 0.0)


def mom(n, s1, s2):
    """Generalised Pareto shape and scale by the method of moments from the count, sum and sum of squares
    of the excesses (arrays allowed): ``xi = (1 - m^2 / v) / 2``, ``sigma = m (1 - xi)``."""
    n, s1, s2 = (np.asarray(v, dtype=float) for v in (n, s1, s2))
    with np.errstate(divide="ignore", invalid="ignore"):
        m = s1 / n
        v = s2 / n - m * m
        xi = np.where(v > 0, 0.5 * (1.0 - m * m / v), 0.0)
        sigma = m * (1.0 - xi)
    return xi, sigma


def fit(values: np.ndarray, p: float) -> tuple[float, Tail]:
    """The level a block maximum exceeds with probability ``p``, from ``values`` (all blocks, pooled)."""
    x = np.sort(np.asarray(values, dtype=float).ravel())
    n = len(x)
    if n == 0:
        return math.inf, Tail(EMPIRICAL, math.inf, 0.0, 0.0, 0.0)
    if n * p >= N_EMPIRICAL or p >= 1.0:
        k = min(n, max(1, int(round(n * p))))  # the k-th largest: k / n of the data at or above it
        return float(x[n - k]), Tail(EMPIRICAL, float(x[n - k]), k / n, 0.0, 0.0)
    share = min(1.0, max(TAIL_SHARE, TAIL_MIN / n))
    k = max(2, int(round(share * n)))
    u = float(x[n - k - 1]) if k < n else float(x[0]) - 1e-12 * max(abs(float(x[0])), 1e-300)
    y = x[x > u] - u
    q = len(y) / n
    xi, sigma = mom(len(y), float(y.sum()), float((y * y).sum()))
    xi, sigma = float(xi), float(sigma)
    if not (sigma > 0 and math.isfinite(sigma)):  # no spread above u: the data's largest, just above
        return float(x[-1]) * (1 + 1e-9) + 1e-300, Tail(EMPIRICAL, float(x[-1]), 1.0 / n, 0.0, 0.0)
    if abs(xi) < 1e-9:
        thr = u - sigma * math.log(p / q)
    else:
        thr = u + sigma / xi * ((p / q) ** (-xi) - 1.0)
    return float(thr), Tail(TAIL, u, q, xi, sigma)


def tail_check(values: np.ndarray, tail: Tail, k: int = 10) -> dict | None:
    """The fitted tail against the data's own extremes: the expected number of block maxima at or above the
    ``k``-th largest, and whether ``k`` is consistent with it (inside the central 95 % Poisson interval of
    a count with that mean). None for an empirical threshold."""
    if tail.kind != TAIL:
        return None
    x = np.sort(np.asarray(values, dtype=float).ravel())
    n = len(x)
    k = min(k, n)
    level = float(x[n - k])
    expected = float(n * gpd_exceed(level, tail.u, tail.q, tail.xi, tail.sigma))
    lo, hi = poisson_interval_of_mean(k)
    return {"level": level, "observed": k, "expected": expected, "consistent": bool(lo <= expected <= hi)}


def poisson_interval_of_mean(k: int, conf: float = CONFIDENCE) -> tuple[float, float]:
    """The exact (Garwood) interval of a Poisson mean from a count ``k``."""
    from scipy.stats import chi2

    a = 1.0 - conf
    lo = 0.0 if k == 0 else 0.5 * float(chi2.ppf(a / 2, 2 * k))
    hi = 0.5 * float(chi2.ppf(1 - a / 2, 2 * k + 2))
    return lo, hi


def startup_blocks(X: np.ndarray, whole: np.ndarray, starts: np.ndarray, transient: float, T: float) -> int:
    """The index (into the valid blocks) of the last start-up block, or -1: a block before the reference
    (whole blocks starting in the second half of ``[transient, T)``) with more paths above the reference's
    90 % quantile than ``STARTUP_SIGMAS`` binomial sigmas allow."""
    mid = transient + 0.5 * (T - transient)
    ref = whole & (starts >= mid)
    if ref.sum() < 2:
        ref = whole.copy()
        ref[: len(ref) // 2] = False
    if not ref.any():
        return -1
    q = float(np.quantile(X[:, ref], _REF_QUANTILE))
    P = X.shape[0]
    limit = (1 - _REF_QUANTILE) * P + STARTUP_SIGMAS * math.sqrt(_REF_QUANTILE * (1 - _REF_QUANTILE) * P)
    first_ref = int(np.flatnonzero(ref)[0])
    flagged = [b for b in range(first_ref) if np.sum(X[:, b] > q) > limit]
    return max(flagged) if flagged else -1


@dataclass(frozen=True)
class FaultCalibration:
    """One fault's thresholds: ``threshold`` from ``steady_from`` on, and per start-up block ``(start, stop,
    threshold)`` (sample times, stop exclusive), with the promise and how it was found."""

    threshold: float
    steady_from: float
    startup: tuple[tuple[float, float, float], ...]
    startup_samples: tuple[tuple[int, int, float], ...]
    kind: str
    all_empirical: bool
    rate_interval: tuple[float, float]
    rate_expected: float
    tail_check: dict | None
    blocks_steady: int


def calibrate_fault(BM: np.ndarray, edges, dt: float, transient: float, T: float, rate: float,
                    weights: np.ndarray) -> FaultCalibration:  # fmt: skip
    """Thresholds of one fault from its block maxima ``BM`` (paths, blocks) over the blocks ``edges`` (first
    and last sample of each), at ``rate`` alarms per unit time after ``transient``; ``weights`` (replicates,
    paths): the bootstrap's Poisson weights."""
    edges = np.asarray(edges, dtype=int)
    k0 = int(math.ceil(transient / dt - 1e-9))  # the first sample at or after the transient
    lo = np.maximum(edges[:, 0], k0)
    n_after = np.maximum(edges[:, 1] - lo + 1, 0)
    E = int(np.max(edges[:, 1] - edges[:, 0] + 1))
    valid = n_after > 0
    idx = np.flatnonzero(valid)
    X = BM[:, idx]
    dur = n_after[idx] * dt
    whole = n_after[idx] == E
    starts = lo[idx] * dt
    last = startup_blocks(X, whole, starts, transient, T)
    steady = np.arange(len(idx)) > last
    steady_whole = steady & whole
    L = E * dt
    if steady_whole.any():
        # the steady blocks merged in runs of STEADY_MERGE (the maximum of each run): an alarm that lasts across a
        # block's end is one alarm, not two, and merged blocks see such ends a third as often
        cols = np.flatnonzero(steady_whole)
        g = max(1, min(STEADY_MERGE, len(cols)))
        runs = [cols[i : i + g] for i in range(0, len(cols) - g + 1, g)]
        g_steady = Group(np.column_stack([X[:, r].max(axis=1) for r in runs]), g * L)
    else:  # no whole steady block: the steady blocks as they are
        g_steady = Group(X[:, steady], float(np.max(dur[steady])) if steady.any() else L)
    D_steady = float(dur[steady].sum())
    p = 1.0 - math.exp(-rate * g_steady.L)
    thr, tail = fit(g_steady.X, p)
    groups = [(g_steady, thr, tail, D_steady / g_steady.L)]  # (group, threshold, tail, blocks' worth)
    startup, segments = [], []
    for b in range(last + 1):
        g = Group(X[:, b : b + 1], float(dur[b]))
        tb, tl = fit(g.X, 1.0 - math.exp(-rate * g.L))
        tb = max(tb, thr)
        groups.append((g, tb, tl, 1.0))
        startup.append((float(starts[b]), float(starts[b] + dur[b]), float(tb)))
        segments.append((int(lo[idx[b]]), int(lo[idx[b]] + n_after[idx[b]]), float(tb)))
    span = max(T - transient, 1e-300)
    expected, reps = 0.0, np.zeros(weights.shape[0])
    for g, th, tl, nblocks in groups:
        st = g.stats(tl.u, [th])  # (paths, 4)
        m = g.X.shape[1]
        W = weights @ st  # (replicates, 4)
        wsum = weights.sum(1) * m
        ones = st.sum(0)
        pe = _exceed(tl, th, ones[0], ones[1], ones[2], ones[3], st.shape[0] * m)
        expected += nblocks * -math.log1p(-min(pe, 1 - 1e-15))
        pr = _exceed(tl, th, W[:, 0], W[:, 1], W[:, 2], W[:, 3], wsum)
        reps += nblocks * -np.log1p(-np.minimum(pr, 1 - 1e-15))
    a = (1 - CONFIDENCE) / 2
    interval = (float(np.quantile(reps, a)) / span, float(np.quantile(reps, 1 - a)) / span)
    return FaultCalibration(
        threshold=float(thr),
        steady_from=float(starts[last + 1]) if last + 1 < len(starts) else float(T),
        startup=tuple(startup),
        startup_samples=tuple(segments),
        kind=tail.kind,
        all_empirical=all(tl.kind == EMPIRICAL for _, _, tl, _ in groups),
        rate_interval=interval,
        rate_expected=expected / span,
        tail_check=tail_check(g_steady.X, tail),
        blocks_steady=int(g_steady.X.size),
    )


def _exceed(tail: Tail, level, n_u, s1, s2, n_level, n_total):
    """P(block maximum >= level) from the group's statistics (scalars, or arrays over replicates)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        frac = np.asarray(n_level, dtype=float) / n_total
        if tail.kind == EMPIRICAL or level <= tail.u:
            return frac
        xi, sigma = mom(n_u, s1, s2)
        q = np.asarray(n_u, dtype=float) / n_total
        return gpd_exceed(level, tail.u, q, xi, sigma)


def bootstrap_weights(seed: int, paths: int, tag: int, replicates: int = BOOTSTRAP) -> np.ndarray:
    """Poisson(1) weights (replicates, paths): path p's weights are row p of a (paths, replicates) draw of
    ``numpy.random.default_rng([seed, tag])``, so they do not depend on how the paths were split."""
    rng = np.random.default_rng([int(seed), int(tag)])
    return np.ascontiguousarray(rng.poisson(1.0, (paths, replicates)).T.astype(float))


def calibrate(BM: np.ndarray, edges, dt: float, transient: float, T: float, rate: float, fault_names, seed: int,
              time_unit: str | None = None, paths0: int = 0):  # fmt: skip
    """Per fault a :class:`FaultCalibration` and its ``detection`` entry of the metrics document, from the
    calibration paths' block maxima; :func:`promise` completes the entries with the alarms counted at the
    thresholds, and :func:`._reduce.finalize` with the run's measured rates."""
    P = BM.shape[0]
    weights = bootstrap_weights(seed, P, tag=0x39CA1)
    cal_time = P * (T - transient)
    hours = cal_time * hours_per_unit(time_unit)
    out, entries = [], []
    for j, name in enumerate(fault_names):
        fc = calibrate_fault(BM[:, :, j], edges, dt, transient, T, rate, weights)
        out.append(fc)
        how = (
            f"{METHOD_TEXT[fc.kind]} over {fc.blocks_steady} steady block maxima from t = {fc.steady_from:.4g}"
            + (f", {len(fc.startup)} start-up blocks with their own thresholds" if fc.startup else "")
        )
        entries.append({
            "fault": name,
            "threshold": fc.threshold if math.isfinite(fc.threshold) else None,
            "false_alarm_rate": None,
            "false_alarm_rate_asked": rate,
            "false_alarm_rate_interval": None,
            "false_alarm_rate_calibration": None,
            "false_alarm_rate_model": fc.rate_expected,
            "false_alarm_rate_model_interval": list(fc.rate_interval),
            "false_alarm_rate_ftc_run": None,
            "calibration_paths": int(P),
            "calibration_first_path": int(paths0),
            "calibration_time": cal_time,
            "calibration_hours": hours,
            "calibration_method": METHOD_TEXT[fc.kind] if fc.all_empirical or fc.kind != EMPIRICAL
            else f"{METHOD_TEXT[EMPIRICAL]} (start-up blocks: {METHOD_TEXT[TAIL]})",
            "tail_check": fc.tail_check,
            "steady_from": fc.steady_from,
            "startup_thresholds": [{"start": a, "stop": b, "threshold": v} for a, b, v in fc.startup],
            "calibration_peak_max": float(np.max(BM[:, :, j])) if BM.size else None,
            "min_detectable_fault": None,
            "rule": RULE.format(t0=transient, h=HYSTERESIS, n=P, hours=hours, rate=rate, how=how),
        })  # fmt: skip
    return out, entries


def promise(cals, entries, raised: np.ndarray, exposure_per_path: float, seed: int) -> None:
    """The rate each fault's thresholds promise, into ``entries``: the alarms the documented rule raised at
    them on the calibration paths (``raised``, paths x faults, over ``exposure_per_path`` each), their exact
    Poisson interval widened by the bootstrap over the paths; where a threshold was extrapolated (a tail
    fit), also widened to the model's own interval (the count at a level set beyond the data says little)."""
    from ._intervals import rate_intervals

    P = raised.shape[0]
    ivs = rate_intervals(
        seed, [raised[:, j] for j in range(raised.shape[1])], [exposure_per_path] * raised.shape[1]
    )
    for j, (fc, e) in enumerate(zip(cals, entries)):
        count = float(np.sum(raised[:, j]))
        e["false_alarm_count_calibration"] = int(round(count))
        e["false_alarm_rate_calibration"] = (
            count / (P * exposure_per_path) if P and exposure_per_path > 0 else None
        )
        iv = ivs[j]
        if iv is not None and not fc.all_empirical:
            iv = [min(iv[0], fc.rate_interval[0]), max(iv[1], fc.rate_interval[1])]
        e["false_alarm_rate_interval"] = iv


def startup_segments(cals) -> tuple[tuple[int, int, int, float], ...]:
    """The start-up thresholds as ``(fault, first sample, last sample + 1, threshold)``."""
    return tuple((j, k0, k1, v) for j, c in enumerate(cals) for k0, k1, v in c.startup_samples)


def threshold_column(steady, segments, nsamp: int) -> np.ndarray:
    """The thresholds at every sample (samples, faults): a start-up block's own, else the steady one."""
    out = np.tile(np.asarray(steady, dtype=float)[None, :], (nsamp, 1))
    for j, k0, k1, v in segments:
        out[int(k0) : int(k1), int(j)] = float(v)
    return out
