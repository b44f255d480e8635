"""Speed of the Monte Carlo engine against the per-path engine (:mod:`._perpath`), sdeint and a plain Python loop,
all measured in one process.

A *path-step* is one sample of the closed loop for one path, all three runs (fault-free,
faulty without and with tolerant control). The baselines integrate the very same closed-loop
SDE — the same sample Function, called interpreted from Python once per step (what a user
writes by hand around CasADi) — on a few paths, and are scaled to path-steps per second.
"""

from __future__ import annotations

import os
import time

import casadi as ca
import numpy as np

from fte_casadi.design import Design
from fte_casadi.errors import SimulationError
from fte_casadi.sim import UniformNoise
from fte_casadi.sim._engine import SCALES, Prepared, closed_loop_sample, plant_schedule, resolve_dt, simulate

from ._anatomy import libm_share, op_counts, peak_flops
from ._handloop import bench_fast
from ._perpath import monte_carlo, simulate_per_path

__all__ = ["bench"]  # public: docs/api.md


def baseline_functions(design: Design, plant, scenario, dt: float):
    """``(drift_fn, diffusion_fn, state0)`` of the closed loop as one SDE ``ds = a(s, t) dt + b(s, t) dw``.

    Built from the engine's own sample Function: ``next(s) = s + a dt + b dW`` is affine in dW,
    so ``a = (next(s, dW=0) - s) / dt`` and ``b = next(s, dW=1) - next(s, dW=0)`` reproduce the
    Euler-Maruyama step exactly. The unknown input of step k is drawn once, up front.
    """
    nsteps = int(round(scenario.T / dt))
    t = np.arange(nsteps + 2000) * dt
    sched = plant_schedule(design, plant, scenario, t, dt)
    fn, lay = closed_loop_sample(design, plant, dt, sched)
    FP = sched.stacked()
    rng = np.random.default_rng(0)
    ui = scenario.unknown_input
    pad = nsteps + 2000  # the engine pads its last block
    D = (
        rng.uniform(-ui.amplitude, ui.amplitude, (lay.ld, pad))
        if isinstance(ui, UniformNoise)
        else np.zeros((lay.ld, pad))
    )

    def k_of(tt):
        return min(int(round(tt / dt)), nsteps)

    def a(s, tt):
        k = k_of(tt)
        w = np.concatenate([[0.0], D[:, k]])
        return (np.asarray(fn(s, w, FP[:, k])[0]).ravel() - s) / dt

    def b(s, tt):
        k = k_of(tt)
        w0 = np.concatenate([[0.0], D[:, k]])
        w1 = np.concatenate([[1.0], D[:, k]])
        return (np.asarray(fn(s, w1, FP[:, k])[0]) - np.asarray(fn(s, w0, FP[:, k])[0])).reshape(-1, 1)

    x0 = np.asarray(plant.x0 if scenario.x0 is None else scenario.x0, float)
    s0 = np.zeros(lay.ns)
    y0 = np.asarray(plant.C) @ x0
    z0 = np.concatenate([x0, np.zeros(lay.nbar - plant.n)]) - np.asarray(design.H) @ y0
    for r in range(3):
        o = r * lay.run_state
        s0[o : o + plant.n] = x0
        s0[o + plant.n : o + plant.n + lay.nbar] = z0
    return fn, a, b, s0, D, FP, lay


def bench(
    design: Design | None = None,
    plant=None,
    scenario=None,
    *,
    paths: int = 1000,
    baseline_paths: int = 2,
    repeats: int = 3,
    seed: int = 0,
    threads: int | None = None,
    horizon: float | None = None,
    fast_repeats: int = 15,
) -> dict:
    """The manipulator scenario (T = 10 s, dt = 1 ms, three runs; ``horizon`` shortens T for tests):
    the vectorised engine against the per-path engine on ``paths`` paths (whole ``simulate``
    calls, random numbers included, compilation excluded: each engine runs once first; then both
    ``repeats`` times, interleaved, and the best of each is kept), and the
    sdeint and plain-Python baselines on ``baseline_paths`` paths, scaled to path-steps per second.
    ``design``, ``plant``, ``scenario``: the caller's (this module does not import the plants).
    The fast mode (``exact=False``) is timed the same way, and in one thread against a hand-vectorised
    C loop over the same arithmetic (:func:`._handloop.bench_fast`, ``fast_repeats`` repetitions).
    """
    scen = scenario
    if horizon is not None:
        scen = scen.until(float(horizon))
    dt, nsteps, _ = resolve_dt(design, scen, None)
    kw = dict(paths=paths, seed=seed, progress=False, threads=threads)
    vkw = dict(kw, detect=False)  # the engine alone: the per-path baseline calibrates no detection thresholds

    def timed(fn):
        t0 = time.perf_counter()
        out = fn()
        return time.perf_counter() - t0, out

    first_vec, _ = timed(lambda: simulate(design, plant, scen, **vkw))
    first_pp, _ = timed(lambda: simulate_per_path(design, plant, scen, **kw))
    first_fast, _ = timed(lambda: simulate(design, plant, scen, exact=False, **vkw))
    # interleaved, best of `repeats` each: the engines see the same load on a shared machine
    vec_walls, pp_walls, fast_walls = [], [], []
    for _ in range(max(1, int(repeats))):
        vec_walls.append(timed(lambda: simulate(design, plant, scen, **vkw))[0])
        pp_walls.append(timed(lambda: simulate_per_path(design, plant, scen, **kw))[0])
        fast_walls.append(timed(lambda: simulate(design, plant, scen, exact=False, **vkw))[0])
    vec_wall, pp_wall, fast_wall = min(vec_walls), min(pp_walls), min(fast_walls)
    prep = Prepared(design, plant, scen, dt, nsteps, dict(SCALES))
    ops = op_counts(prep.engine_function, plant.ld)
    flops = ops["flops"]
    vec_rate = paths * nsteps / vec_wall
    peak = peak_flops()
    anatomy = libm_share(prep, paths=min(paths, 256), seed=seed)
    hand = bench_fast(prep, paths=min(paths, 64), seed=seed, repeats=fast_repeats)
    engine_rate = vec_rate
    fn, a, b, s0, D, FP, lay = baseline_functions(design, plant, scen, dt)
    rng = np.random.default_rng(seed)
    tspan = np.arange(nsteps + 1) * dt

    # (a) sdeint's itoEuler on the same closed-loop SDE
    try:
        import sdeint
    except ImportError:
        raise SimulationError(
            "the Monte Carlo benchmark compares against sdeint, which is not installed: "
            "pip install 'fte_casadi[bench]' (or the [test] extra)"
        ) from None

    t0 = time.perf_counter()
    for _ in range(baseline_paths):
        dW = np.sqrt(dt) * rng.standard_normal((nsteps, 1))
        sde = sdeint.itoEuler(a, b, s0, tspan, dW=dW)
    sde_wall = time.perf_counter() - t0

    # the engine's core on the same noise as the last sdeint path
    def fill(W, k0):
        L = W.shape[1]
        W[:] = 0.0
        k1 = min(k0 + L, nsteps)
        W[0, : k1 - k0, 0] = dW[k0:k1, 0]
        W[0, : k1 - k0, 1:] = D[:, k0:k1].T

    rec, _ = monte_carlo(fn, s0[None, :], FP, nsteps, 1, fill, dt=dt)
    diff = max(
        float(
            np.max(
                np.abs(
                    rec[0, :, r * lay.run_rec : r * lay.run_rec + plant.n]
                    - sde[:, r * lay.run_state : r * lay.run_state + plant.n]
                )
            )
        )
        for r in range(3)
    )
    sde_rate = baseline_paths * nsteps / sde_wall

    # (b) a plain Python loop calling the sample Function once per step
    t0 = time.perf_counter()
    for _ in range(baseline_paths):
        s = s0.copy()
        dW = np.sqrt(dt) * rng.standard_normal(nsteps)
        for k in range(nsteps):
            s = np.asarray(fn(s, np.concatenate([[dW[k]], D[:, k]]), FP[:, k])[0]).ravel()
    loop_wall = time.perf_counter() - t0
    loop_rate = baseline_paths * nsteps / loop_wall

    return {
        "scenario": f"{plant.name}, T = {scen.T:g}, dt = {dt:g}, three runs per path",
        "engine": {
            "paths": paths,
            "steps": nsteps,
            "wall_s": vec_wall,
            "wall_s_all_repeats": vec_walls,
            "first_call_wall_s": first_vec,
            "path_steps_per_s": vec_rate,
            "threads": threads or min(8, os.cpu_count() or 1),
            "flops_per_path_step": flops,
            "operations_per_path_step": ops,
            "fraction_of_peak": vec_rate * flops / peak["flops_per_s"],
            "peak_assumed": peak,
            "one_thread": anatomy,
        },
        "per_path_engine": {
            "paths": paths,
            "wall_s": pp_wall,
            "wall_s_all_repeats": pp_walls,
            "first_call_wall_s": first_pp,
            "path_steps_per_s": paths * nsteps / pp_wall,
        },
        "speedup_vs_per_path": pp_wall / vec_wall,
        "fast_mode": {
            "paths": paths,
            "wall_s": fast_wall,
            "wall_s_all_repeats": fast_walls,
            "first_call_wall_s": first_fast,
            "path_steps_per_s": paths * nsteps / fast_wall,
            "speedup_vs_exact": vec_wall / fast_wall,
            "one_thread_vs_hand_loop": hand,
        },
        "sdeint_itoEuler": {
            "paths": baseline_paths,
            "wall_s": sde_wall,
            "path_steps_per_s": sde_rate,
            "scaled_wall_s_for_engine_paths": paths * nsteps / sde_rate,
        },
        "python_loop": {
            "paths": baseline_paths,
            "wall_s": loop_wall,
            "path_steps_per_s": loop_rate,
            "scaled_wall_s_for_engine_paths": paths * nsteps / loop_rate,
        },
        "speedup_vs_sdeint": engine_rate / sde_rate,
        "max_abs_diff_engine_vs_sdeint": diff,
        "speedup_vs_python_loop": engine_rate / loop_rate,
        "sample_instructions": int(fn.n_instructions()),
        "casadi": ca.__version__,
    }
