"""The uncertainty of a Monte Carlo figure over its paths: 95 % intervals of ratios, rates and probabilities.

- A **ratio of sums over the paths** (``sqrt(sum_p a_p / sum_p b_p)``, every RMS ratio of the metrics
  document) gets a bootstrap interval over the paths: the pairs ``(a_p, b_p)`` are sorted (by ``a_p``, then
  ``b_p``), path ``i`` of that order takes the ``i``-th row of Poisson(1) weights ``W`` (paths, replicates)
  drawn by ``numpy.random.default_rng([seed, TAG])``, each replicate is ``sqrt(sum_i W_ir a_i / sum_i W_ir
  b_i)``, and the interval is the replicates' 2.5 and 97.5 percentiles (numpy's linear interpolation). The
  order makes it depend on the set of paths only, not on how they were numbered or split.
- A **rate** (alarms per unit time) gets the exact Poisson (Garwood) interval of its count, widened where
  the bootstrap over the paths' counts (as above, with ``sum W c / sum W`` per unit exposure) is wider: alarms
  that cluster on some paths are not Poisson.
- A **probability** (paths detected / paths) gets the exact binomial (Clopper-Pearson) interval.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = []  # public: docs/api.md

#: bootstrap replicates, the confidence of every interval, and the tag of the weights' generator
REPLICATES = 1000
CONFIDENCE = 0.95
TAG = 39
#: paths per block of weights (memory: this many x REPLICATES doubles)
_BLOCK = 4096


def _percentiles(v: np.ndarray) -> list[float] | None:
    v = v[np.isfinite(v)]
    if len(v) < 0.5 * REPLICATES:  # most replicates undefined (a denominator zero): no interval
        return None
    a = 100 * (1 - CONFIDENCE) / 2
    lo, hi = np.percentile(v, [a, 100 - a])
    return [float(lo), float(hi)]


def replicate_sums(seed: int, columns: list[tuple[np.ndarray, np.ndarray]]) -> list[np.ndarray]:
    """For each pair ``(a, b)`` of per-path arrays: the bootstrap replicates of ``(sum W a, sum W b)`` as an
    array (REPLICATES, 2), the paths taken in the order of ``(a, b)`` (see the module)."""
    if not columns:
        return []
    P = len(columns[0][0])
    orders = [np.lexsort((np.asarray(b, float), np.asarray(a, float))) for a, b in columns]
    Z = [
        np.column_stack([np.asarray(a, float)[o], np.asarray(b, float)[o]])
        for (a, b), o in zip(columns, orders)
    ]
    Zs = np.hstack(Z)  # (P, 2 K), each pair in its own order
    rng = np.random.default_rng([int(seed), TAG])
    out = np.zeros((REPLICATES, Zs.shape[1]))
    for i0 in range(0, P, _BLOCK):
        i1 = min(P, i0 + _BLOCK)
        W = rng.poisson(1.0, (i1 - i0, REPLICATES)).astype(float)
        out += W.T @ Zs[i0:i1]
    return [out[:, 2 * k : 2 * k + 2] for k in range(len(columns))]


def ratio_intervals(seed: int, pairs: list[tuple[np.ndarray, np.ndarray]]) -> list[list[float] | None]:
    """95 % bootstrap intervals of ``sqrt(sum a / sum b)`` for each per-path pair ``(a, b)``."""
    out = []
    for s in replicate_sums(seed, pairs):
        with np.errstate(divide="ignore", invalid="ignore"):
            r = np.sqrt(s[:, 0] / s[:, 1])
        out.append(_percentiles(np.where(s[:, 1] > 0, r, np.nan)))
    return out


def garwood(k: float, exposure: float, conf: float = CONFIDENCE) -> list[float] | None:
    """The exact interval of a Poisson rate from ``k`` events over ``exposure``."""
    from scipy.stats import chi2

    if not exposure > 0:
        return None
    a = 1.0 - conf
    k = int(round(k))
    lo = 0.0 if k == 0 else 0.5 * float(chi2.ppf(a / 2, 2 * k))
    hi = 0.5 * float(chi2.ppf(1 - a / 2, 2 * k + 2))
    return [lo / exposure, hi / exposure]


def rate_intervals(
    seed: int, counts: list[np.ndarray], exposure_per_path: list[float]
) -> list[list[float] | None]:
    """For per-path alarm counts over the same exposure per path: the Garwood interval of the total,
    widened to the bootstrap interval over the paths where that is wider."""
    pairs = [(np.asarray(c, float), np.full(len(c), e)) for c, e in zip(counts, exposure_per_path)]
    out = []
    for (c, e_p), s in zip(pairs, replicate_sums(seed, pairs)):
        g = garwood(float(np.sum(c)), float(np.sum(e_p)))
        if g is None:
            out.append(None)
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            b = _percentiles(np.where(s[:, 1] > 0, s[:, 0] / s[:, 1], np.nan))
        out.append(g if b is None else [min(g[0], b[0]), max(g[1], b[1])])
    return out


def clopper_pearson(k: int, n: int, conf: float = CONFIDENCE) -> list[float] | None:
    """The exact binomial interval of a probability from ``k`` successes in ``n`` trials."""
    from scipy.stats import beta

    if n <= 0:
        return None
    a = 1.0 - conf
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return [lo, hi]


def above(interval, value: float) -> bool:
    """The interval lies above ``value`` (a figure worse than ``value``, not a tie)."""
    return interval is not None and math.isfinite(interval[0]) and interval[0] > value
