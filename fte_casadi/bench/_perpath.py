"""The per-path Monte Carlo engine: one compiled block per path, mapped over paths.

Not part of the package: it is the reference the vectorised engine (:mod:`fte_casadi.sim._engine`)
is tested against — the same trajectories for the same random numbers (tests/test_sim_engine.py
imports it from here) — and the baseline ``fte bench`` measures that engine against in the same
process. One CasADi Function computes a sample of the closed loop for one path and
all three runs; it is accumulated over blocks of records (``mapaccum``), compiled once (cached)
and mapped over paths with CasADi's thread map; Python fills the random numbers path by path
(child generators ``rng.spawn``) and keeps every recorded sample of every path in memory.
"""

from __future__ import annotations

import hashlib
import math
import os
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import casadi as ca
import numpy as np
from tqdm import tqdm

from fte_casadi._toolchain import cache_dir, find_compiler
from fte_casadi.design import Design
from fte_casadi.errors import ParameterError, SimulationError
from fte_casadi.model import Plant
from fte_casadi.sim import Scenario, Sinusoid, UniformNoise
from fte_casadi.sim._engine import (
    PathLayout,
    _check_settings,
    closed_loop_sample,
    plant_schedule,
    resolve_dt,
    result_names,
)
from fte_casadi.sim._result import RUNS, SimulationResult

__all__ = []  # public: docs/api.md

#: recorded path-samples kept in memory by default (per run); more paths -> coarser recording
_RECORD_BUDGET = 500_000
#: ... and at most about this many samples per path
_RECORD_PER_PATH = 20_001


def compiled(fn: ca.Function, *, flags: tuple[str, ...] = ("-O2",)) -> tuple[ca.Function, bool]:
    """Return ``(function, is_compiled)``: ``fn`` as C in a shared library, or ``fn`` itself."""
    cc = find_compiler()
    if cc is None:
        warnings.warn(
            "no C compiler found (cc, gcc, clang or $CC): the Monte Carlo runs interpreted, "
            "10-100x slower; install a C compiler for full speed",
            RuntimeWarning,
            stacklevel=3,
        )
        return fn, False
    name = fn.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        cg.add(fn)
        src_path = Path(tmp) / f"{name}.c"
        cg.generate(str(Path(tmp)) + os.sep)
        src = src_path.read_text()
        key = hashlib.sha256((src + cc + " ".join(flags) + ca.__version__).encode()).hexdigest()[:20]
        folder = cache_dir()
        lib = folder / f"{name}_{key}.so"
        if not lib.exists():
            folder.mkdir(parents=True, exist_ok=True)
            out = Path(tmp) / "lib.so"
            cmd = [cc, *flags, "-shared", "-fPIC", "-o", str(out), str(src_path), "-lm"]
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
            except (OSError, subprocess.TimeoutExpired) as exc:
                proc = None
                err = str(exc)
            if proc is None or proc.returncode != 0:
                err = proc.stderr[-2000:] if proc is not None else err
                warnings.warn(
                    f"compiling the closed loop with {cc} failed; running interpreted (slower). Compiler said: {err}",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return fn, False
            # atomic publish: parallel runs may compile the same library
            fd, tmp_lib = tempfile.mkstemp(dir=folder, suffix=".so.tmp")
            os.close(fd)
            shutil.copyfile(out, tmp_lib)
            os.replace(tmp_lib, lib)
    return ca.external(name, str(lib)), True


def _block_function(sample: ca.Function, every: int, records: int) -> ca.Function:
    """``(state, W, FP) -> (state_end, REC)`` over ``records`` records of ``every`` steps each."""
    ns, nw = sample.size1_in(0), sample.size1_in(1)
    acc = sample.mapaccum("fte_cl_acc", every)
    S = ca.MX.sym("state", ns)
    W = ca.MX.sym("w", nw, every)
    FP = ca.MX.sym("fp", sample.size1_in(2), every)
    nxt, rec = acc(S, W, FP)
    one = ca.Function("fte_cl_rec", [S, W, FP], [nxt[:, -1], rec[:, 0]])
    blk = one.mapaccum("fte_cl_blk", records)
    S2 = ca.MX.sym("state", ns)
    W2 = ca.MX.sym("w", nw, every * records)
    FP2 = ca.MX.sym("fp", sample.size1_in(2), every * records)
    nxt2, rec2 = blk(S2, W2, FP2)
    return ca.Function(
        f"fte_cl_block_{every}x{records}",
        [S2, W2, FP2],
        [nxt2[:, -1], rec2],
        ["state", "w", "fp"],
        ["state_end", "rec"],
    )


def simulate_per_path(
    design: Design,
    plant: Plant,
    scenario: Scenario,
    *,
    paths: int,
    seed: int,
    dt: float | None = None,
    progress: bool = True,
    record_every: int | None = None,
    threads: int | None = None,
    rng: np.random.Generator | None = None,
) -> SimulationResult:
    """Monte Carlo of ``scenario`` on the nonlinear ``plant`` closed by ``design``: three runs per path.

    Parameters
    ----------
    design, plant, scenario
        The observer/controller, the nonlinear plant it was designed for, the experiment.
    paths : int
        Number of Brownian paths.
    seed : int
        Seed of the ``numpy.random.Generator`` (recorded in the result and the metrics);
        path ``i`` uses child generator ``i`` of ``numpy.random.default_rng(seed)``.
    dt : float, optional
        Euler-Maruyama step and controller sample time; default the scenario's, lowered to a
        round value below ``ts_max / 2`` when the design cannot run at it (said in ``notes``).
        An explicit ``dt`` above the design's ``checks["ts_max"]`` is refused.
    progress : bool
        Show a progress bar on stderr when the run lasts more than about a second.
    record_every : int, optional
        Keep every k-th sample; default 1 unless paths x samples exceeds ~5e5 or a path ~2e4 samples.
    threads : int, optional
        Threads of the path map (default: the CPU count, at most 8).
    rng : numpy.random.Generator, optional
        Use this generator instead of ``default_rng(seed)`` (``seed`` is then only recorded).

    Returns
    -------
    SimulationResult
    """
    t_wall = time.perf_counter()
    _check_settings(design, plant, paths, seed, dt)
    paths, seed = int(paths), int(seed)
    dt, nsteps, notes = resolve_dt(design, scenario, dt)
    if record_every is None:
        record_every = max(
            1, math.ceil(paths * (nsteps + 1) / _RECORD_BUDGET), math.ceil((nsteps + 1) / _RECORD_PER_PATH)
        )
    if not isinstance(record_every, int) or record_every < 1:
        raise ParameterError(f"record_every must be a positive integer; got {record_every!r}")
    nrec = nsteps // record_every + 1
    t_all = np.arange(nsteps + record_every * 1000 + 1) * dt  # covers the padded last block
    sched = plant_schedule(design, plant, scenario, t_all, dt)
    sample, lay = closed_loop_sample(design, plant, dt, sched)

    # initial states; per path three child generators (x0 noise, dW, d): a path's noise does not
    # depend on the block size nor on how many paths run
    root = np.random.default_rng(seed) if rng is None else rng
    gens = [g.spawn(3) for g in root.spawn(paths)]
    x0n = np.asarray(plant.x0 if scenario.x0 is None else scenario.x0, dtype=float)
    if x0n.shape != (plant.n,):
        raise SimulationError(f"scenario x0 has {x0n.size} entries; the plant has {plant.n} states")
    x0 = np.stack([x0n + scenario.x0_noise * g[0].standard_normal(plant.n) for g in gens])
    H = np.asarray(design.H)
    xb_nom = np.concatenate([x0n, np.zeros(lay.nbar - plant.n)])
    state = np.zeros((paths, lay.ns))
    for r in range(3):
        o = r * lay.run_state
        state[:, o : o + plant.n] = x0
        if scenario.observer_init == "nominal":
            y0 = x0 @ np.asarray(plant.C).T
            state[:, o + plant.n : o + plant.n + lay.nbar] = xb_nom - y0 @ H.T
    ui = scenario.unknown_input
    sq = math.sqrt(dt)

    def fill(W: np.ndarray, k0: int) -> None:
        L = W.shape[1]
        for q, g in enumerate(gens):
            W[q, :, 0] = sq * g[1].standard_normal(L)
            if lay.ld and isinstance(ui, UniformNoise):
                W[q, :, 1:] = g[2].uniform(-ui.amplitude, ui.amplitude, (L, lay.ld))
        if lay.ld and isinstance(ui, Sinusoid):
            tt = t_all[k0 : k0 + L]
            W[:, :, 1:] = (ui.amplitude * np.sin(2 * np.pi * ui.frequency * tt + ui.phase))[None, :, None]

    def check(rec: np.ndarray, t: np.ndarray) -> None:
        _check_divergence(rec, lay, scenario.divergence_bound, t, plant.name)

    rec_all, is_compiled = monte_carlo(
        sample.expand(),
        state,
        sched.stacked(),
        nsteps,
        record_every,
        fill,
        dt=dt,
        threads=threads,
        progress=progress,
        desc=f"simulate {plant.name}",
        check=check,
    )
    if not is_compiled:
        notes.append("no C compiler: the closed loop ran interpreted")
    every = record_every
    runs = lay.split_record(rec_all)
    names = result_names(plant)
    return SimulationResult(
        plant=plant.name,
        t=np.arange(nrec) * every * dt,
        dt=dt,
        T=float(scenario.T),
        seed=seed,
        paths=paths,
        record_every=every,
        scenario=scenario,
        design=design,
        names=names,
        wall_s=time.perf_counter() - t_wall,
        compiled=is_compiled,
        notes=tuple(notes),
        **runs,
    )


def monte_carlo(
    sample: ca.Function,
    state0: np.ndarray,
    FP: np.ndarray,
    nsteps: int,
    every: int,
    fill,
    *,
    dt: float,
    threads: int | None = None,
    progress: bool = False,
    desc: str = "simulate",
    check=None,
) -> tuple[np.ndarray, bool]:
    """Run ``sample: (state, w, fp) -> (state_next, rec)`` for ``nsteps`` steps on every path.

    ``state0``: (paths, ns). ``FP``: (nfp, >= padded steps) per-step inputs shared by all paths.
    ``fill(W, k0)`` writes the per-path inputs ``W`` (paths, L, nw) of steps ``k0 .. k0+L-1``.
    Records the ``rec`` output at samples 0, every, 2 every, ... <= nsteps; returns
    ``(rec (paths, samples, nrec), compiled)``. ``check(rec_block, t_block)`` may raise.
    This is the whole Euler-Maruyama engine: compiled block, path map, zero-copy buffers.
    """
    paths = state0.shape[0]
    nrec = nsteps // every + 1
    records = max(1, min(nrec, 1000 // every if every < 1000 else 1))
    nblocks = math.ceil(nrec / records)
    L = records * every
    if FP.shape[1] < nblocks * L:
        FP = np.concatenate([FP, np.repeat(FP[:, -1:], nblocks * L - FP.shape[1], axis=1)], axis=1)
    block, is_compiled = compiled(_block_function(sample, every, records))
    nthreads = threads or min(8, os.cpu_count() or 1)
    par = "thread" if nthreads > 1 and paths > 1 else "serial"
    opts = {"max_num_threads": nthreads} if par == "thread" else {}
    mapped = block.map("fte_cl_paths", par, paths, [2], [], opts)  # FP shared by all paths
    # Zero-copy calls (Function.buffer): a CasADi (rows x cols) dense matrix is column-major,
    # i.e. a C-contiguous numpy array of shape (cols, rows).
    nrv = sample.size1_out(1)
    rec_all = np.empty((paths, nblocks * records, nrv))
    FPt = np.ascontiguousarray(FP.T)
    S_in = np.ascontiguousarray(state0, dtype=float)
    S_out = np.empty_like(S_in)
    W = np.zeros((paths, L, sample.size1_in(1)))
    REC = np.empty((paths, records, nrv))
    buf, run_block = mapped.buffer()
    buf.set_arg(0, memoryview(S_in))
    buf.set_arg(1, memoryview(W))
    buf.set_res(0, memoryview(S_out))
    buf.set_res(1, memoryview(REC))
    bar = tqdm(
        total=nblocks * L * paths,
        disable=not progress,
        delay=1.0,
        file=sys.stderr,
        unit=" path-steps",
        unit_scale=True,
        desc=desc,
    )
    try:
        for b in range(nblocks):
            k0 = b * L
            fill(W, k0)
            fp_blk = np.ascontiguousarray(FPt[k0 : k0 + L])
            buf.set_arg(2, memoryview(fp_blk))
            run_block()
            rec_all[:, b * records : (b + 1) * records, :] = REC
            if check is not None:
                check(REC, (k0 + every * np.arange(records)) * dt)
            S_in[...] = S_out
            bar.update(L * paths)
    finally:
        bar.close()
    return rec_all[:, :nrec, :], is_compiled


def _check_divergence(rec: np.ndarray, lay: PathLayout, bound: float, t: np.ndarray, plant: str) -> None:
    """Stop with a message naming the first diverging path and time (rec: (paths, samples, nrec))."""
    bad_run = []
    for r in range(3):
        blk = rec[:, :, r * lay.run_rec : (r + 1) * lay.run_rec]
        xs = blk[:, :, : lay.n]
        bad_run.append(~np.isfinite(blk).all(axis=2) | ~(np.abs(xs) <= bound).all(axis=2))
    bad = bad_run[0] | bad_run[1] | bad_run[2]
    if bad.any():
        where = np.argwhere(bad)
        path, k = where[np.argmin(where[:, 1])]
        runs = ", ".join(RUNS[r] for r in range(3) if bad_run[r][path, k])
        raise SimulationError(
            f"{plant}: path {int(path)} diverged at t = {t[k]:.6g} (run {runs}: state NaN/Inf or |x| > {bound:g}); "
            "the closed loop is unstable for this design and step: check the design's certificates, lower dt, "
            "or shorten the fault"
        )
