"""The calibration engine: the fault-free closed loop alone, reduced to block maxima of each residual.

Detection thresholds are set from fault-free paths that are not the run's own (:mod:`._detect`). The
calibration needs many of them (hours of the plant's time for one false alarm per hour), so it runs a
closed loop of its own: the fault-free run only (the deployed, tolerant step on the fault-free plant,
the same Euler-Maruyama step and the same random numbers as the fault-free run of :mod:`._engine`), and
per fault one running maximum of the residual ``|fhat_j|`` after the start-up allowance. The running
maximum is recorded and reset every ``E`` samples, so a path leaves only its *block maxima* (about
``T / E`` numbers per fault) and its per-path sums of ``fhat_j^2``: memory is bounded by
``paths x blocks x faults``, no trajectory is kept.

Block ``m >= 1`` holds the samples ``(m - 1) E < k <= m E``; the samples after the last whole block
form a last, shorter block (read from the final state). The block length is about the observer's
slowest time constant (:func:`block_samples`), so that the start-up's decay shows block by block.
"""

from __future__ import annotations

import functools
import math
import os
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ..step import StepParameters, step_function

__all__ = []  # public: docs/api.md

#: blocks at most this many per horizon (the block length is the observer's time constant, or longer)
MAX_BLOCKS = 128


def block_samples(tau: float, T: float, dt: float) -> int:
    """Samples per block: the observer's slowest time constant ``tau`` (at least ``T / MAX_BLOCKS``)."""
    length = max(tau if math.isfinite(tau) else T / 16.0, T / MAX_BLOCKS)
    return max(1, int(round(length / dt)))


@dataclass(frozen=True)
class Calibration:
    """A run's detection: the steady thresholds per fault, the start-up blocks' own thresholds as ``(fault,
    first sample, last sample + 1, threshold)``, the metrics document's ``detection`` entries, each fault's
    :class:`._detect.FaultCalibration` and the rate asked. Reusable by runs of the same fault-free behaviour
    (other fault sizes)."""

    thresholds: np.ndarray
    segments: tuple
    entries: list
    faults: tuple
    rate: float


class CalibrationEngine:
    """The compiled fault-free loop of a :class:`._engine.Prepared` (built once; cached on disk as the engine is).

    ``(state, w, sh) -> (next, rec, incr)``: state ``[x (n); z (nz); running maxima (lf); alarms (lf)]``;
    ``sh = [after; reset; d_deterministic (ld); noise std (nv); thresholds (lf)]``; ``rec``: per fault the
    running maximum including this sample (what a record at this sample closes); ``incr``: per fault the
    alarms raised at this sample by the documented rule (off until ``after``, raised at ``|fhat_j| >=
    threshold``, cleared below ``HYSTERESIS`` of it; none where the threshold is infinite)."""

    def __init__(self, prep):
        from ._reduce import HYSTERESIS
        from ._vector import VectorEngine

        design, plant, dt = prep.design, prep.plant, prep.dt
        n, lf, ld, p = plant.n, plant.lf, plant.ld, plant.p
        nz = design.nz
        nv = prep.lay.nv
        # the design's numbers as parameters: one engine per structure (as Prepared's)
        numbers = StepParameters()
        step = step_function(design, dt, tolerant=True, numbers=numbers)
        dt_ = numbers.scalar("sample_time", dt)
        drift, diff = plant.drift_function(), plant.diffusion_function()
        C = ca.DM(np.asarray(plant.C, float))
        ns = n + nz + 2 * lf
        S = ca.SX.sym("state", ns)
        w = ca.SX.sym("w", 1 + ld + nv)
        sh = ca.SX.sym("sh", 2 + ld + nv + lf)
        x, z, cur, al = S[:n], S[n : n + nz], S[n + nz : n + nz + lf], S[n + nz + lf :]
        after, reset = sh[0], sh[1]
        thr = sh[2 + ld + nv :]
        dW = w[0]
        # (no unknown input: an empty column, since w[1:1] of a 1 x 1 w is 1 x 0 and sh[2:2] is 0 x 1)
        d = w[1 : 1 + ld] + sh[2 : 2 + ld] if ld else ca.SX(0, 1)
        v = w[1 + ld :] * sh[2 + ld : 2 + ld + nv] if nv else ca.DM.zeros(p)
        y = ca.mtimes(C, x) + v
        z_next, u, xbh, _yc, _s = step(z, y)
        f0 = ca.DM.zeros(lf)
        d2 = ca.DM.zeros(plant.d2.numel())
        x_next = x + drift(x, u, d, f0) * dt_ + diff(x, u, f0, d2) * dW
        a = ca.fabs(xbh[n + lf :])
        closed = ca.fmax(cur, after * a)
        cur_next = ca.if_else(reset, ca.DM.zeros(lf), closed)
        raised = after * (al == 0) * (a >= thr)
        al_next = after * ca.if_else(al != 0, a >= HYSTERESIS * thr, a >= thr)
        F = ca.Function(
            "fte_cal",
            [S, w, sh, numbers.symbols],
            [ca.vertcat(x_next, z_next, cur_next, al_next), closed, raised],
            {"cse": True},
        ).expand()
        self.function = F
        self.ns, self.n, self.nz, self.lf, self.ld, self.nv = ns, n, nz, lf, ld, nv
        self.engine = VectorEngine(
            F, list(range(n)), name="fte_cal", exact=prep.exact, nv=nv, par=numbers.values
        )


def shared_inputs(prep, E: int, thresholds: np.ndarray | None = None) -> np.ndarray:
    """The calibration engine's shared inputs (samples, 2 + ld + nv + lf) for the run ``prep`` (its scales):
    ``after`` (t >= transient), ``reset`` (k a multiple of ``E``), the deterministic unknown input, the
    measurement noise's standard deviations and the thresholds at each sample (samples, lf; None: infinite,
    no alarms)."""
    nsamp = prep.SH.shape[0]
    k = np.arange(nsamp)
    after = prep.masks.M[prep.masks.row("after")]
    a, b = prep.cols["d"]
    c, e = prep.cols["vstd"]
    thr = np.full((nsamp, prep.plant.lf), np.inf) if thresholds is None else np.asarray(thresholds, float)
    return np.ascontiguousarray(
        np.column_stack([after, (k % E == 0).astype(float), prep.SH[:, a:b], prep.SH[:, c:e], thr])
    )


def initial_states(prep, paths: np.ndarray, seed: int) -> np.ndarray:
    """The fault-free run's initial states of :meth:`._engine.Prepared.initial_states`; maxima and alarms at zero."""
    full = prep.initial_states(paths, seed)
    n, nz, lf = prep.plant.n, prep.design.nz, prep.plant.lf
    out = np.zeros((len(paths), n + nz + 2 * lf))
    out[:, : n + nz] = full[:, : n + nz]  # the fault-free run comes first in the engine's state
    return out


def block_edges(nsamp: int, E: int) -> list[tuple[int, int]]:
    """The blocks' first and last samples (inclusive): ``[0, 0]``, ``((m - 1) E, m E]``, then the rest."""
    out = [(0, 0)]
    last = 0
    for m in range(1, (nsamp - 1) // E + 1):
        out.append(((m - 1) * E + 1, m * E))
        last = m * E
    if last < nsamp - 1:
        out.append((last + 1, nsamp - 1))
    return out


def run_block_maxima(
    cal: CalibrationEngine, prep, E: int, path0: int, count: int, seed: int, thresholds=None
):
    """Paths ``path0 .. path0 + count - 1``: ``(BM, RAISED, DIV)``, the block maxima (count, blocks, lf), the
    alarms raised per path and fault at ``thresholds`` (samples, lf; None: none) and the divergence marks."""
    paths = np.arange(path0, path0 + count)
    S0 = initial_states(prep, paths, seed)
    SH = shared_inputs(prep, E, thresholds)
    S1, acc, div, rec = cal.engine.run(path0, S0, seed, SH, prep.sqdt, prep.damp,
                                       prep.scenario.divergence_bound, E)  # fmt: skip
    nsamp = SH.shape[0]
    tail = [] if (nsamp - 1) % E == 0 else [S1[:, None, cal.n + cal.nz : cal.n + cal.nz + cal.lf]]
    BM = np.concatenate([rec, *tail], axis=1)
    return BM, acc, div


def _column(prep, spec):
    from ._detect import threshold_column

    return None if spec is None else threshold_column(spec[0], spec[1], prep.SH.shape[0])


def run_calibration(prep, paths: int, seed: int, path0: int, E: int, *, threads=None, chunk=None, bar=None,
                    scheduler=None, thresholds=None, cluster_task=None):  # fmt: skip
    """Block maxima, and alarms raised at ``thresholds`` (``(steady per fault, start-up segments)``; None:
    none), of ``paths`` fault-free paths from ``path0`` on, in chunks on threads, or on a cluster's workers
    with ``cluster_task`` (:func:`._engine.calibration_task`)."""
    from concurrent.futures import ThreadPoolExecutor

    from ._vector import LANES, auto_chunk

    nsamp = prep.SH.shape[0]
    nblk = len(block_edges(nsamp, E))
    BM = np.empty((paths, nblk, prep.plant.lf))
    RA = np.empty((paths, prep.plant.lf))
    DIV = np.empty(paths, dtype=np.int_)

    def keep(a, out):
        bm, ra, dv = out
        BM[a : a + len(dv)], RA[a : a + len(dv)], DIV[a : a + len(dv)] = bm, ra, dv
        if bar is not None:
            bar.update(len(dv))

    if scheduler is not None:
        from ._cluster import run_on_cluster

        task = functools.partial(cluster_task, exact=prep.exact, block=int(E), thresholds=thresholds)
        for a, out in run_on_cluster(scheduler, prep.design, prep.plant, prep.scenario, prep.dt, prep.scales, seed,
                                     paths, chunk, task, path0=path0):  # fmt: skip
            keep(a, out)
        return BM, RA, DIV
    cal = prep.calibration_engine()
    column = _column(prep, thresholds)
    nthreads = threads or min(8, os.cpu_count() or 1)
    nsteps = max(nsamp - 1, 1)
    chunk = chunk or min(auto_chunk(paths, nthreads), max(LANES, LANES * (750_000 // (LANES * nsteps))))
    pool = ThreadPoolExecutor(max_workers=nthreads)
    try:
        futs = [(a, pool.submit(run_block_maxima, cal, prep, E, path0 + a, min(chunk, paths - a), seed, column))
                for a in range(0, paths, chunk)]  # fmt: skip
        for a, fut in futs:
            keep(a, fut.result())
    except BaseException:
        pool.shutdown(wait=False, cancel_futures=True)
        raise
    pool.shutdown()
    return BM, RA, DIV


def calibration(
    prep, rate: float, seed: int, path0: int, given: int | None, *, diverged, **kw
) -> Calibration:
    """The thresholds of the run ``prep`` at ``rate`` (:mod:`._detect`): the block maxima of the calibration
    paths ``path0, path0 + 1, ...`` (as many as :func:`._detect.calibration_paths` asks, or ``given``), then the
    same paths again, their alarms counted by the documented rule at these thresholds: the promise.
    ``diverged(div)`` raises on a diverged path; ``kw``: :func:`run_calibration`'s options."""
    from ._detect import calibrate, calibration_paths, promise, startup_segments

    T, transient = prep.nsteps * prep.dt, prep.masks.transient
    E = block_samples(prep.allowances.tau, T, prep.dt)
    n = calibration_paths(rate, E * prep.dt, prep.nsteps, given=given)
    BM, _, div = run_calibration(prep, n, seed, path0, E, **kw)
    diverged(div)
    cals, entries = calibrate(BM, block_edges(prep.nsteps + 1, E), prep.dt, transient, T, rate,
                              prep.plant.fault_names, seed, time_unit=prep.plant.time_unit, paths0=path0)  # fmt: skip
    steady = np.array([c.threshold for c in cals], dtype=float)
    segments = startup_segments(cals)
    _, raised, _ = run_calibration(prep, n, seed, path0, E, thresholds=(tuple(steady), segments), **kw)
    n_after = float(np.sum(prep.masks.M[prep.masks.row("after")]))
    promise(cals, entries, raised, n_after * prep.dt, seed)
    return Calibration(steady, segments, entries, tuple(cals), rate)
