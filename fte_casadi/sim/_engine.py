"""Euler-Maruyama Monte Carlo of the closed loop on the *nonlinear* plant, vectorised across paths.

One CasADi Function computes one sample of the closed loop for one path and all three runs
(fault-free, faulty without tolerant control, faulty with it), which share the Brownian
increment, the unknown input and the initial state. Within a sample, for each run::

    y_k     = C x_k + Df f_k^sensor             (sensor faults depend on x and t only)
    (z_{k+1}, u_k, xbarhat_k, yc_k, s_k) = step(z_k, y_k)     -- fte_casadi.step, the single source of truth
    f_k     = f_k^sensor + f_k^actuator(u_k)    (loss of effectiveness needs u_k; u_k is the clipped input)
    x_{k+1} = x_k + drift(x_k, u_k, d_k, f_k) dt + g(x_k, u_k, f_k, 0) dW_k

The fault-free run uses the tolerant step too (the deployed controller, never faulted); the
faulty run without tolerant control uses ``step_function(..., tolerant=False)``.

:func:`simulate` appends the metric summands of :mod:`._reduce` to that Function and runs it in the
lane engine of :mod:`._vector` (C over chunks of paths, random numbers drawn in the loop by the
counter-based generator of :mod:`._rng`, so path i's noise depends only on (seed, i)). Memory is
bounded: each path keeps its state and its metric sums; full trajectories are recorded only for
the example paths the figures use (all paths with ``record_all``). Chunks of paths run on threads
or, with ``scheduler``, on the workers of a dask.distributed cluster (:mod:`._cluster`); the metrics
are the same either way. The per-path engine it is tested against lives in the repository's
benchmarks/perpath.py, not in the package.
"""

from __future__ import annotations

import functools
import json
import math
import os
import sys
import time
from typing import TYPE_CHECKING, NamedTuple

import casadi as ca
import numpy as np
from tqdm import tqdm

from .._keywords import with_keywords
from .._rounding import series_floor
from ..design import Design
from ..errors import ParameterError, SimulationError
from ..model import Plant
from ..step import StepParameters, step_function
from ._c_range import accepted_measurements
from ._cluster import plant_from_bytes, run_on_cluster
from ._detect import default_rate
from ._masks import allowances, masks
from ._options import SCALES as SCALES
from ._options import SimulateOptions, check_scales
from ._reduce import finalize, monitor, sensor_gains
from ._result import RUNS, RunData, SimulationResult
from ._scenario import FaultSchedule, Scenario, fault_schedule
from ._start import observer_start
from ._vector import CHUNK as CHUNK
from ._vector import auto_chunk as auto_chunk

if TYPE_CHECKING:  # an optional dependency (the [dask] extra)
    import distributed

__all__ = ["simulate"]  # public: docs/api.md

#: at most about this many recorded samples per example path
_RECORD_PER_PATH = 20_001


class PathLayout:
    """Sizes and offsets of the closed-loop state and record of one path."""

    def __init__(
        self, n: int, nbar: int, lf: int, m: int, p: int, ld: int, nv: int = 0, nz: int | None = None
    ):
        self.n, self.nbar, self.lf, self.m, self.p, self.ld, self.nv = n, nbar, lf, m, p, ld, nv
        #: the step's state: z (nbar), then a latched accommodation gate's latches (Design.nz)
        self.nz = nbar if nz is None else int(nz)
        self.run_state = n + self.nz + lf  # x, z (and latches), sensor memory
        self.ns = 3 * self.run_state
        self.sizes = {"x": n, "xbarhat": nbar, "f": lf, "u": m, "y": p, "yc": p, "ucomp": m}
        self.run_rec = sum(self.sizes.values())
        self.nrec = 3 * self.run_rec
        self.nw = 1 + ld + nv  # dW, d, measurement noise

    def split_record(self, rec: np.ndarray) -> dict[str, RunData]:
        """``rec``: (paths, samples, nrec) -> one RunData per run, arrays (paths, samples, size) (views)."""
        out = {}
        off = 0
        for run in RUNS:
            sig = {}
            for name, size in self.sizes.items():
                sig[name] = rec[:, :, off : off + size]
                off += size
            out[run] = RunData(**sig)
        return out


def closed_loop_sample(
    design: Design, plant: Plant, dt: float, sched: FaultSchedule, noise: bool = False,
    numbers: StepParameters | None = None,
) -> tuple[ca.Function, PathLayout]:  # fmt: skip
    """``(state, w, fp) -> (state_next, record)``: one sample of all three runs for one path.

    ``w = [dW; d]``, or with ``noise`` ``[dW; d; v]`` (``v``: the measurement noise of each output, added
    to ``y``; the three runs share it), ``fp`` the fault coefficients of this sample
    (:meth:`FaultSchedule.stacked`). A stuck sensor freezes the reading it had, noise included.
    With ``numbers`` (:class:`fte_casadi.step.StepParameters`), ``(state, w, fp, par) -> ...``: the design's
    numbers and the step ``dt`` are read from ``par`` (``numbers.values``), not folded in as constants.
    """
    n, m, p, lf, ld = plant.n, plant.m, plant.p, plant.lf, plant.ld
    nbar = int(design.dims.nbar)
    nz = design.nz
    lay = PathLayout(n, nbar, lf, m, p, ld, nv=p if noise else 0, nz=nz)
    drift = plant.drift_function()
    diff = plant.diffusion_function()
    steps = {
        "ftc": step_function(design, dt, tolerant=True, numbers=numbers),
        "no_ftc": step_function(design, dt, tolerant=False, numbers=numbers),
    }
    dt_ = dt if numbers is None else numbers.scalar("sample_time", dt)
    C, Df = np.asarray(plant.C, float), np.asarray(plant.Df, float)
    S = ca.SX.sym("state", lay.ns)
    w = ca.SX.sym("w", lay.nw)
    fp = ca.SX.sym("fp", 4 * lf)
    dW, d = w[0], w[1 : 1 + ld]
    v = w[1 + ld :] if noise else ca.DM.zeros(p)
    a, lu, st, la = fp[:lf], fp[lf : 2 * lf], fp[2 * lf : 3 * lf], fp[3 * lf :]
    d2 = ca.DM.zeros(plant.d2.numel())
    nexts, recs = [], []
    for r, run in enumerate(RUNS):
        o = r * lay.run_state
        x, z, mem = S[o : o + n], S[o + n : o + n + nz], S[o + n + nz : o + lay.run_state]
        Cx = ca.mtimes(ca.DM(C), x) + v  # the reading before sensor faults
        faulty = run != "free"
        fs, mem_next = [], []
        for j in range(lf):
            if not faulty:
                fs.append(ca.SX(0.0))
                mem_next.append(mem[j])
                continue
            fj = a[j]
            k = sched.output_index[j]
            if k >= 0:
                held = ca.if_else(la[j] > 0.5, Cx[k], mem[j])
                fj = fj + st[j] * (held - Cx[k]) / sched.output_gain[j]
                mem_next.append(held)
            else:
                mem_next.append(mem[j])
            fs.append(fj)
        f_pre = ca.vertcat(*fs) if lf else ca.SX(0, 1)
        y = Cx + ca.mtimes(ca.DM(Df), f_pre)
        z_next, u, xbh, yc, _s = steps["no_ftc" if run == "no_ftc" else "ftc"](z, y)
        # the compensation this run's step applies: u less what the step without tolerant control gives at the
        # same z and y (after saturation; zero in the run without it)
        ucomp = ca.SX.zeros(m) if run == "no_ftc" else u - steps["no_ftc"](z, y)[1]
        f_all = []
        for j in range(lf):
            i = sched.input_index[j]
            f_all.append(f_pre[j] + lu[j] * u[i] if (faulty and i >= 0) else f_pre[j])
        f = ca.vertcat(*f_all) if lf else ca.SX(0, 1)
        x_next = x + drift(x, u, d, f) * dt_ + diff(x, u, f, d2) * dW
        nexts += [x_next, z_next, ca.vertcat(*mem_next) if lf else ca.SX(0, 1)]
        recs += [x, xbh, f, u, y, yc, ucomp]
    ins = [S, w, fp] if numbers is None else [S, w, fp, numbers.symbols]
    names = ["state", "w", "fp", "par"][: len(ins)]
    fn = ca.Function("fte_cl_sample", ins, [ca.vertcat(*nexts), ca.vertcat(*recs)], names, ["next", "rec"])
    return fn, lay


def _check_settings(design: Design, plant: Plant, paths, seed, dt):
    _check_counts(paths, seed)
    if dt is not None and not (isinstance(dt, (int, float)) and math.isfinite(dt) and dt > 0):
        raise SimulationError(f"time step dt must be a positive number; got {dt!r}")
    dims = design.dims
    want = {"n": plant.n, "m": plant.m, "p": plant.p, "lf": plant.lf}
    bad = {k: (int(getattr(dims, k)), v) for k, v in want.items() if int(getattr(dims, k)) != v}
    if bad:
        txt = ", ".join(f"{k}: design {a} vs plant {b}" for k, (a, b) in bad.items())
        raise SimulationError(
            f"the design does not fit the plant {plant.name!r} ({txt}); design this plant again"
        )
    if not np.allclose(np.asarray(design.C), plant.C) or not np.allclose(np.asarray(design.Df), plant.Df):
        raise SimulationError(
            f"the design's C or Df differ from the plant {plant.name!r}'s; design this plant again"
        )


def plant_schedule(
    design: Design, plant: Plant, scenario: Scenario, t: np.ndarray, dt: float
) -> FaultSchedule:
    """The scenario's fault profiles resolved against this plant and design, sampled at ``t``."""
    return fault_schedule(
        scenario, plant.fault_names, plant.fault_kinds, design.local_models[0].B, design.local_models[0].Bf,
        np.asarray(plant.Df), plant.input_names, t, dt,
        u_operating=getattr(plant, "u_operating", None), u_ref=design.u_ref,
    )  # fmt: skip


def result_names(plant: Plant) -> dict:
    """The signal names and units a SimulationResult carries (figures, reports)."""
    return {
        "states": list(plant.state_names),
        "state_units": list(plant.state_units),
        "inputs": list(plant.input_names),
        "outputs": list(plant.output_names),
        "output_units": list(plant.output_units),
        "faults": list(plant.fault_names),
        "fault_kinds": list(plant.fault_kinds),
        "time_unit": plant.time_unit,
    }


def design_sample_time(design: Design, scenario: Scenario) -> float:
    """The sample time the design was made (and certified) for: its recorded one, else the scenario's step."""
    sample_time = design.observer.sample_time
    return float(sample_time) if sample_time else float(scenario.dt)


def resolve_dt(design: Design, scenario: Scenario, dt: float | None) -> tuple[float, int, list[str]]:
    """The step (the design's sample time, lowered below its ts_max when it must be), the number of
    steps, and notes. An explicit ``dt`` above ts_max is refused."""
    notes = []
    ts_max = float(design.checks.get("ts_max", math.inf) or math.inf)
    if dt is None:
        dt = design_sample_time(design, scenario)
        if dt > ts_max:
            new = series_floor(ts_max / 2)
            while abs(scenario.T / new - round(scenario.T / new)) > 1e-9 * scenario.T / new:
                new = series_floor(new * 0.999)
            notes.append(
                f"the design's sample time {dt:g} exceeds its ts_max = {ts_max:.4g}; using dt = {new:g}"
            )
            dt = new
    elif dt > ts_max:
        raise SimulationError(
            f"time step dt = {dt:g} exceeds the largest sample time for which the design's discrete observer is "
            f"stable (checks.ts_max = {ts_max:.4g}); choose --dt below {ts_max:.4g}"
        )
    dt = float(dt)
    nsteps = int(round(scenario.T / dt))
    if nsteps < 1 or abs(nsteps * dt - scenario.T) > 1e-6 * scenario.T + 1e-9:
        raise SimulationError(
            f"the horizon T = {scenario.T:g} is not a whole number of steps dt = {dt:g}; choose dt dividing T"
        )
    return dt, nsteps, notes


def step_change(design: Design, scenario: Scenario, dt: float, given: float | None) -> dict | None:
    """``{"from", "to", "why"}`` when the step run differs from the design's sample time, else None."""
    sample_time = design_sample_time(design, scenario)
    if abs(dt - sample_time) <= 1e-12 * sample_time:
        return None
    why = (
        "--dt given"
        if given is not None
        else "the design's sample time exceeds its ts_max (lowered below it)"
    )
    if given is not None and design.observer.sample_time is None:
        why = "--dt given (the design records no sample time: compared with the scenario's step)"
    return {"from": sample_time, "to": float(dt), "why": why}


def _scales(scales: dict | None, scenario: Scenario | None = None) -> dict:
    """The factors with their defaults, validated (against ``scenario``'s faults when given)."""
    out = check_scales(scales)
    if scenario is not None and scenario.measurement_noise is None and out["measurement_noise_scale"] != 1.0:
        raise ParameterError(
            f"measurement_noise_scale = {out['measurement_noise_scale']:g}: scenario {scenario.name!r} has no measurement "
            "noise to scale; give the scenario measurement_noise=[std per output] (or fte simulate --measurement-noise)"
        )
    for fp in scenario.faults if scenario is not None else ():
        fp.check_scale(out["fault_scale"])
    return out


def _shared_columns(lf: int, nm: int, ld: int, nv: int) -> dict[str, tuple[int, int]]:
    """The columns of the shared inputs: the fault coefficients (4 lf), the masks (nm), the time, the detection
    thresholds (lf), the deterministic unknown input (ld), the measurement noise's deviations (nv)."""
    cols = {"fp": (0, 4 * lf)}
    cols["mask"] = (4 * lf, 4 * lf + nm)
    cols["t"] = (cols["mask"][1], cols["mask"][1] + 1)
    cols["thr"] = (cols["t"][1], cols["t"][1] + lf)
    cols["d"] = (cols["thr"][1], cols["thr"][1] + ld)
    cols["vstd"] = (cols["d"][1], cols["d"][1] + nv)
    return cols


class Prepared:
    """Everything a run needs that does not depend on the paths: built once per (design, scenario, dt),
    the same in-process and on a cluster worker (which rebuilds it from the documents).

    The shared inputs ``SH`` (samples, columns): the fault coefficients, the masks, the deterministic
    unknown input, the time, the detection thresholds (per fault; inf: none) and the measurement
    noise's standard deviations (per output, when the scenario has noise)."""

    def __init__(
        self, design: Design, plant: Plant, scenario: Scenario, dt: float, nsteps: int, scales: dict,
        exact: bool = True, thresholds=None,
    ):  # fmt: skip
        from ._vector import VectorEngine

        self.design, self.plant, self.scenario, self.dt, self.nsteps = design, plant, scenario, dt, nsteps
        self._cal_box: list = []  # the calibration engine, built on first use, shared by copies
        self.scales = scales
        self.exact = bool(exact)
        nsamp = nsteps + 1
        self.t = np.arange(nsamp) * dt
        sched = plant_schedule(design, plant, scenario, self.t, dt)
        noise = scenario.measurement_noise is not None
        # the design's numbers are the engine's parameters, not constants in its C: one compiled engine serves every
        # design of the same structure (fte tune's trials, a design made again)
        numbers = StepParameters()
        sample, lay = closed_loop_sample(design, plant, dt, sched, noise=noise, numbers=numbers)
        self.par = numbers.values
        self.lay = lay
        FP = sched.stacked()  # (4 lf, samples): rows a, lu, st, la
        lf, ld = plant.lf, plant.ld
        FP[: 3 * lf] *= scales["fault_scale"]  # bias/drift, loss, stuck deviation; not the latch
        self.allowances = allowances(design, scenario)
        self.masks = masks(self.t, scenario, plant.fault_names, self.allowances)
        ui = scenario.unknown_input
        ddet = np.zeros((ld, nsamp))
        self.damp = 0.0
        if ld and ui is not None:  # d = damp * U[-1, 1] + ddet
            terms = ui.terms(self.t, scales["d_scale"])
            self.damp = float(terms.uniform)
            if terms.deterministic is not None:
                ddet[:] = terms.deterministic
        self.sqdt = math.sqrt(dt) * scales["noise_scale"]
        thr = np.full(lf, np.inf) if thresholds is None else np.asarray(thresholds, dtype=float)
        self.threshold_spec = (tuple(float(v) for v in thr), ())
        vstd = np.zeros((lay.nv, nsamp))
        if noise:  # v = vstd * N(0, 1)
            vstd[:] = scenario.measurement_noise.deviations(self.t, scales["measurement_noise_scale"])
        self.cols = _shared_columns(lf, self.masks.M.shape[0], ld, lay.nv)
        self.SH = np.ascontiguousarray(
            np.vstack([FP, self.masks.M, self.t[None, :], np.repeat(thr[:, None], nsamp, 1), ddet, vstd]).T
        )
        region = (np.asarray(plant.region_lo, float), np.asarray(plant.region_hi, float))
        #: the measurements the generated C accepts at this sample time (outside them its step returns 3)
        self.y_range = accepted_measurements(design, dt)
        self.monitor = monitor(
            lay, self.masks, np.asarray(plant.C, float), design.input_limits, region, self.y_range
        )
        self.names = self.monitor.names
        F = self.engine_function = self._engine_function(sample, ld, lf)
        xs = [r * lay.run_state + j for r in range(3) for j in range(lay.n)]
        self.engine = VectorEngine(F, xs, name="fte_mc", exact=self.exact, nv=lay.nv, par=self.par)
        self.notes = (self.engine.note,) if self.engine.note else ()

    def _engine_function(self, sample: ca.Function, ld: int, lf: int) -> ca.Function:
        """``(state + monitor, w, sh, par) -> (next, rec, incr, pm)``: the closed loop's sample followed by the
        monitor, the unknown input and the measurement noise completed from the shared inputs ``sh``; ``par``: the
        design's numbers (:attr:`par`)."""
        lay, c = self.lay, self.cols
        S = ca.SX.sym("state", lay.ns + self.monitor.nmon)
        w = ca.SX.sym("w", lay.nw)
        sh = ca.SX.sym("sh", self.SH.shape[1])
        par = ca.SX.sym("par", self.par.size)
        # an empty slice of an SX column can come out 1x0: a plant without unknown inputs (or without measurement
        # noise) gets an explicit 0x1 block
        d_part = w[1 : 1 + ld] + sh[c["d"][0] : c["d"][1]] if ld else ca.SX(0, 1)
        v_part = w[1 + ld :] * sh[c["vstd"][0] : c["vstd"][1]] if lay.nv else ca.SX(0, 1)
        wd = ca.vertcat(w[0], d_part, v_part)
        nxt, rec = sample(S[: lay.ns], wd, sh[: 4 * lf], par)
        mon_next, inc, pm = self.monitor.fn(rec, S[lay.ns :], sh[c["mask"][0] : c["thr"][1]])
        # cse: CasADi merges repeated subexpressions (the sin of a premise that the plant also uses)
        return ca.Function(
            "fte_cl", [S, w, sh, par], [ca.vertcat(nxt, mon_next), rec, inc, pm], {"cse": True}
        ).expand()

    def calibration_engine(self):
        """The compiled fault-free loop that calibrates the detection thresholds (:mod:`._calibrate`), built
        on first use and shared by the copies of this engine (other scales or thresholds)."""
        from ._calibrate import CalibrationEngine

        box = self._cal_box
        if not box:
            box.append(CalibrationEngine(self))
        return box[0]

    @property
    def thresholds(self) -> np.ndarray:
        """The steady detection thresholds (per fault; inf: none)."""
        return np.asarray(self.threshold_spec[0], dtype=float)

    def with_thresholds(self, thresholds, startup=()) -> Prepared:
        """The same compiled engine with other detection thresholds: per fault the steady one (inf: none), and
        the start-up blocks' own as ``(fault, first sample, last sample + 1, threshold)``."""
        import copy

        from ._detect import threshold_column

        out = copy.copy(self)
        out.SH = self.SH.copy()
        a, b = self.cols["thr"]
        steady = tuple(float(v) for v in np.asarray(thresholds, dtype=float))
        segs = tuple((int(j), int(k0), int(k1), float(v)) for j, k0, k1, v in startup)
        out.SH[:, a:b] = threshold_column(steady, segs, out.SH.shape[0])
        out.threshold_spec = (steady, segs)
        return out

    def rescaled(self, scales: dict) -> Prepared:
        """The same compiled engine with other factors: only the shared inputs change (no recompilation)."""
        import copy

        out = copy.copy(self)
        out.scales = scales
        lf = self.plant.lf
        out.SH = self.SH.copy()
        ratio = lambda k: scales[k] / self.scales[k] if self.scales[k] else 0.0  # noqa: E731
        out.SH[:, : 3 * lf] *= ratio("fault_scale")
        a, b = self.cols["d"]
        out.SH[:, a:b] *= ratio("d_scale")
        out.damp = self.damp * ratio("d_scale")
        a, b = self.cols["vstd"]
        out.SH[:, a:b] *= ratio("measurement_noise_scale")
        out.sqdt = math.sqrt(self.dt) * scales["noise_scale"]
        return out

    def with_fault_factors(self, factors) -> Prepared:
        """The same compiled engine with each fault's magnitude multiplied by its own factor (one per fault, in
        the plant's order; on top of ``fault_scale``): e.g. one fault alone at a size, the others absent."""
        import copy

        out = copy.copy(self)
        out.SH = self.SH.copy()
        lf = self.plant.lf
        f = np.asarray(factors, dtype=float)
        for r in range(3):  # bias/drift, loss, stuck deviation; not the latch
            out.SH[:, r * lf : (r + 1) * lf] *= f[None, :]
        return out

    def initial_states(self, paths: np.ndarray, seed: int) -> np.ndarray:
        """(len(paths), ns + nmon): x0 plus its noise (drawn from (seed, path)), observer initialised per
        scenario, the monitor's start."""
        from ._rng import noise_normals, x0_normals

        plant, sc, lay = self.plant, self.scenario, self.lay
        x0n = np.asarray(plant.x0 if sc.x0 is None else sc.x0, dtype=float)
        if x0n.shape != (plant.n,):
            raise SimulationError(f"scenario x0 has {x0n.size} entries; the plant has {plant.n} states")
        x0 = x0n + sc.x0_noise * x0_normals(seed, paths, plant.n)
        state = np.zeros((len(paths), lay.ns + self.monitor.nmon))
        v0 = None
        if lay.nv:  # the first sample's measurement noise, as the engine draws it
            c, e = self.cols["vstd"]
            v0 = noise_normals(seed, paths, 0, plant.ld, lay.nv) * self.SH[0, c:e]
        # the faults' additive part at the first sample (a stuck sensor adds 0 there: it holds that reading)
        a0 = self.SH[0, : plant.lf]
        for r, run in enumerate(RUNS):
            o = r * lay.run_state
            state[:, o : o + plant.n] = x0
            zb = observer_start(self.design, plant, sc, x0, v0, a0 if run != "free" else None)
            if zb is not None:
                state[:, o + plant.n : o + plant.n + lay.nbar] = zb
        state[:, lay.ns :] = self.monitor.mon0()[None, :]
        return state


def run_paths(prep: Prepared, path0: int, count: int, seed: int, every: int = 0):
    """Paths ``path0 .. path0 + count - 1``: ``(ACC, DIV, REC, MON, PM)`` (REC only when ``every > 0``):
    the per-path sums, divergence marks, records, final monitor states, and the per-sample sums over
    these paths."""
    paths = np.arange(path0, path0 + count)
    S0 = prep.initial_states(paths, seed)
    S1, acc, div, rec, pm = prep.engine.run(path0, S0, seed, prep.SH, prep.sqdt, prep.damp,
                                            prep.scenario.divergence_bound, every, pm=True)  # fmt: skip
    if pm is None:
        pm = np.zeros((prep.SH.shape[0], 0))
    return acc, div, rec, S1[:, prep.lay.ns :], pm


@functools.lru_cache(maxsize=8)
def _prepared(design_json: str, plant_blob: bytes, scenario_json: str, dt: float, scales_json: str,
              exact: bool = True):  # fmt: skip
    """The engine of a run, built once per worker process and run description."""
    design = Design.from_dict(json.loads(design_json), source="design sent to a worker")
    plant = plant_from_bytes(plant_blob)
    scenario = Scenario.from_dict(json.loads(scenario_json))
    nsteps = int(round(scenario.T / dt))
    return Prepared(design, plant, scenario, dt, nsteps, json.loads(scales_json), exact=exact)


def chunk_task(design_json: str, plant_blob: bytes, scenario_json: str, dt: float, scales_json: str, seed: int,
               path0: int, count: int, exact: bool = True, thresholds: tuple = ()):  # fmt: skip
    """One chunk on a worker: the per-path metric sums, divergence marks, monitor states and the per-sample
    maxima of ``path0 .. path0 + count - 1`` (``thresholds``: the detection thresholds, ``(steady, start-up
    segments)`` of :meth:`Prepared.with_thresholds`; empty: none)."""
    prep = _prepared(design_json, plant_blob, scenario_json, float(dt), scales_json, bool(exact))
    if thresholds:
        prep = prep.with_thresholds(*thresholds)
    acc, div, _, mon, pm = run_paths(prep, path0, count, seed)
    return acc, div, mon, pm


def calibration_task(design_json: str, plant_blob: bytes, scenario_json: str, dt: float, scales_json: str, seed: int,
                     path0: int, count: int, exact: bool = True, block: int = 1, thresholds=None):  # fmt: skip
    """One chunk of calibration paths on a worker: block maxima, alarms raised at ``thresholds`` and
    divergence marks (:func:`._calibrate.run_block_maxima`)."""
    from ._calibrate import _column, run_block_maxima

    prep = _prepared(design_json, plant_blob, scenario_json, float(dt), scales_json, bool(exact))
    return run_block_maxima(prep.calibration_engine(), prep, int(block), path0, count, seed,
                            _column(prep, thresholds))  # fmt: skip


def check_scenario(plant: Plant, scenario: Scenario) -> None:
    """Refuse a fault window outside [0, T), measurement noise of the wrong size, unknown inputs the plant does not
    have and an x0 outside the plant's region, each with what to do."""
    for fp in scenario.faults:
        if fp.start < 0 or fp.stop > scenario.T:
            raise ParameterError(
                f"scenario {scenario.name!r}: the window [{fp.start:g}, {fp.stop:g}) of fault {fp.fault!r} does not lie "
                f"inside the horizon [0, {scenario.T:g}); shorten the window or lengthen T"
            )
    if scenario.measurement_noise is not None:
        scenario.measurement_noise.check(scenario.name, plant.output_names)
    if scenario.unknown_input is not None and plant.ld == 0:  # it would be dropped without a word
        raise ParameterError(
            f"scenario {scenario.name!r}: it drives unknown inputs ({type(scenario.unknown_input).__name__}) but plant "
            f"{plant.name!r} has none; drop the scenario's unknown_input, or declare the plant's (b.unknown_inputs)"
        )
    x0 = np.asarray(plant.x0 if scenario.x0 is None else scenario.x0, dtype=float)
    lo, hi = np.asarray(plant.region_lo, float), np.asarray(plant.region_hi, float)
    # a bound that is not a finite number (a region the plant leaves open) does not confine x0
    bad = [
        k for k in range(plant.n) if (np.isfinite(lo[k]) and x0[k] < lo[k]) or (np.isfinite(hi[k]) and x0[k] > hi[k])
    ] if x0.shape == lo.shape else []  # fmt: skip
    if bad:
        txt = ", ".join(f"{plant.state_names[k]} = {x0[k]:g} outside [{lo[k]:g}, {hi[k]:g}]" for k in bad)
        raise ParameterError(
            f"scenario {scenario.name!r}: the initial state lies outside the plant's region ({txt}), where the T-S model "
            "is not exact; start inside the region or widen the region (b.region(...)) and design again"
        )


def calibrate_detection(design: Design, plant: Plant, scenario: Scenario, *, paths: int, seed: int,
                        false_alarm_rate: float | None = None, dt: float | None = None, threads: int | None = None,
                        prepared: Prepared | None = None, bar=None, chunk: int | None = None, scheduler=None,
                        calibration_paths: int | None = None):  # fmt: skip
    """Detection thresholds per fault (:class:`._calibrate.Calibration`), from fault-free paths ``paths, paths +
    1, ...`` of ``seed`` (those after the run's own) in the calibration engine (:mod:`._calibrate`), as many as
    :func:`._detect.calibration_paths` asks for the rate (``calibration_paths``: that many)."""
    from ._calibrate import calibration

    rate = default_rate(plant.time_unit) if false_alarm_rate is None else float(false_alarm_rate)
    if not (math.isfinite(rate) and rate > 0):
        raise ParameterError(
            f"false_alarm_rate must be a positive number of alarms per time unit; got {false_alarm_rate!r}"
        )
    cp = calibration_paths
    if cp is not None and (not isinstance(cp, (int, np.integer)) or isinstance(cp, bool) or cp < 2):
        raise ParameterError(f"calibration_paths must be an integer of at least 2; got {cp!r}")
    if prepared is None:
        check_scenario(plant, scenario)
        dt, nsteps, _ = resolve_dt(design, scenario, dt)
        prepared = Prepared(design, plant, scenario, dt, nsteps, _scales(None, scenario))
    return calibration(prepared, rate, seed, int(paths), cp, threads=threads, chunk=chunk, bar=bar,
                       scheduler=scheduler, cluster_task=calibration_task,
                       diverged=lambda div: _diverged(div, plant, prepared.scenario, prepared.dt, int(paths)))  # fmt: skip


def _run_chunks(prep: Prepared, plant: Plant, paths: int, seed: int, path0: int, chunk, threads, scheduler,
                every_all: int, bar) -> tuple:  # fmt: skip
    """Run paths ``path0 .. path0 + paths - 1`` in chunks (threads or a cluster): per-path sums, divergence
    marks, monitor states, the per-sample sums over all of them, and the records when ``every_all``."""
    acc = np.empty((paths, len(prep.names)))
    div = np.empty(paths, dtype=np.int_)
    mon = np.empty((paths, prep.monitor.nmon))
    pm = np.zeros((prep.SH.shape[0], len(prep.monitor.pm_names)))
    nsamp = prep.SH.shape[0]
    rec = np.empty((paths, (nsamp - 1) // every_all + 1, prep.lay.nrec)) if every_all else None

    def keep(a, out):
        ca_, dv, rc, mo, pmx = out
        acc[a : a + len(dv)], div[a : a + len(dv)], mon[a : a + len(dv)] = ca_, dv, mo
        pm[...] += pmx  # chunk by chunk, in path order
        if rc is not None:
            rec[a : a + len(dv)] = rc
        bar.update(len(dv))

    if scheduler is not None:
        task = functools.partial(chunk_task, exact=prep.exact, thresholds=prep.threshold_spec)
        for a, (ca_, dv, mo, pmx) in run_on_cluster(scheduler, prep.design, plant, prep.scenario, prep.dt,
                                                    prep.scales, seed, paths, chunk, task,
                                                    path0=path0):  # fmt: skip
            keep(a, (ca_, dv, None, mo, pmx))
    else:
        from collections import deque
        from concurrent.futures import ThreadPoolExecutor

        from ._vector import LANES

        nthreads = threads or min(8, os.cpu_count() or 1)
        # a chunk is one uninterruptible call of the C engine: at most ~2.5e5 path-steps (~0.1-0.3 s), whole lane
        # vectors, so that a Ctrl-C waits for little; the metrics do not depend on it
        nsteps = max(prep.SH.shape[0] - 1, 1)
        chunk = chunk or min(auto_chunk(paths, nthreads), max(LANES, LANES * (250_000 // (LANES * nsteps))))
        pool = ThreadPoolExecutor(max_workers=nthreads)
        live: deque = deque()  # (first path, future) in path order, a few per thread ahead
        try:
            for a in range(0, paths, chunk):
                live.append(
                    (a, pool.submit(run_paths, prep, path0 + a, min(chunk, paths - a), seed, every_all))
                )
                if len(live) >= 4 * nthreads:
                    a0, fut = live.popleft()
                    keep(a0, fut.result())
            while live:
                a0, fut = live.popleft()
                keep(a0, fut.result())
        except BaseException:  # Ctrl-C or a failed chunk: drop the chunks not started, wait for none
            pool.shutdown(wait=False, cancel_futures=True)
            raise
        pool.shutdown()
    return acc, div, mon, pm, rec


def simulate(design: Design, plant: Plant, scenario: Scenario, *, paths: int, seed: int, dt: float | None = None,
             progress: bool = True, record_paths: int | None = None, record_all: bool = False,
             record_every: int | None = None, threads: int | None = None, chunk: int | None = None,
             scheduler: str | distributed.Client | None = None, scales: dict | None = None,
             prepared: Prepared | None = None, exact: bool = True, detect: bool = True,
             false_alarm_rate: float | None = None, calibration_paths: int | None = None, calibration=None,
             options: SimulateOptions | None = None) -> SimulationResult:  # fmt: skip
    """Monte Carlo of ``scenario`` on the nonlinear ``plant`` closed by ``design``: three runs per path.

    Parameters
    ----------
    design, plant, scenario
        The observer/controller, the nonlinear plant it was designed for, the experiment.
    paths : int
        Number of Brownian paths.
    seed : int
        Seed of the counter-based generator (:mod:`._rng`): path i's noise depends on (seed, i) only.
    options : SimulateOptions, optional
        How the run goes: ``dt``, ``progress``, ``record_paths``, ``record_all``, ``record_every``, ``threads``,
        ``chunk``, ``scheduler``, ``scales``, ``exact``, ``detect``, ``false_alarm_rate``, ``calibration_paths``
        (:class:`~fte_casadi.sim.SimulateOptions` says what each does and its default). Each is also a keyword
        argument of this function; a keyword given with a value other than its default changes the record's.
    prepared : Prepared, optional
        The compiled engine of this (design, scenario, step, factors), built before (in the mode of ``exact``).
    calibration : Calibration, optional
        Thresholds calibrated before (:func:`calibrate_detection`, for the same fault-free behaviour: the
        same design, scenario, step and factors other than ``fault_scale``): used instead of calibrating.

    Returns
    -------
    SimulationResult
        With ``metrics`` (the metrics document over all paths, streamed) and the recorded paths.
    """
    t_wall = time.perf_counter()
    _check_counts(paths, seed)
    o = with_keywords(SimulateOptions, options, dict(
        dt=dt, progress=progress, record_paths=record_paths, record_all=record_all, record_every=record_every,
        threads=threads, chunk=chunk, scheduler=scheduler, scales=scales, exact=exact, detect=detect,
        false_alarm_rate=false_alarm_rate, calibration_paths=calibration_paths))  # fmt: skip
    _check_settings(design, plant, paths, seed, o.dt)
    check_scenario(plant, scenario)
    paths, seed, exact = int(paths), int(seed), bool(o.exact)
    if prepared is not None and prepared.exact != exact:
        raise ParameterError(
            f"the prepared engine was built with exact={prepared.exact}, the run asks for exact={exact}; "
            "prepare the engine in the mode of the run"
        )
    sc = _scales(o.scales, scenario)
    dt, nsteps, notes = resolve_dt(design, scenario, o.dt)
    every, nrec_paths = _record_plan(o, scenario, paths, nsteps + 1, dt, notes)
    prep = prepared or Prepared(design, plant, scenario, dt, nsteps, sc, exact=exact)
    notes += _run_notes(prep, exact)
    rate = default_rate(plant.time_unit) if o.false_alarm_rate is None else float(o.false_alarm_rate)
    ran = _calibrated_run(design, plant, scenario, prep, o, paths, seed, rate, calibration, every, dt, nsteps)
    _diverged(ran.div, plant, scenario, dt, 0)
    rec = ran.rec
    if nrec_paths and rec is None:
        _, _, rec, _, _ = run_paths(ran.prep, 0, nrec_paths, seed, every)
    wall = time.perf_counter() - t_wall
    meta = {"paths": paths, "dt": dt, "T": scenario.T, "seed": seed, "wall_s": wall, "m": plant.m,
            "thresholds": [float(v) for v in ran.thresholds], "detection": ran.detection,
            "tau": prep.allowances.tau if math.isfinite(prep.allowances.tau) else None,
            "y_range": prep.y_range, "sensor_gains": sensor_gains(design),
            "region": (list(plant.region_lo), list(plant.region_hi))}  # fmt: skip
    doc = finalize(ran.acc, ran.mon, ran.pm, prep.t, prep.monitor, prep.masks, meta)
    mn = scenario.measurement_noise
    doc["measurement_noise"] = None if mn is None else mn.reported(sc["measurement_noise_scale"])
    doc["dt_change"] = step_change(design, scenario, dt, o.dt)
    doc["exact"] = exact
    if rec is None:
        rec = np.zeros((0, nsteps // every + 1, prep.lay.nrec))
    return SimulationResult(
        plant=plant.name, t=np.arange(rec.shape[1]) * every * dt, dt=dt, T=float(scenario.T), seed=seed,
        paths=paths, record_every=every, scenario=scenario, design=design, names=result_names(plant), wall_s=wall,
        compiled=True, notes=tuple(notes), metrics=doc, scales=sc,
        region=(np.asarray(plant.region_lo, float), np.asarray(plant.region_hi, float)),
        **prep.lay.split_record(rec),
    )  # fmt: skip


def _check_counts(paths, seed) -> None:
    """Refuse a number of paths that is not a positive integer, a seed that is not a non-negative one."""
    if not isinstance(paths, (int, np.integer)) or isinstance(paths, bool) or paths < 1:
        raise ParameterError(f"paths must be a positive integer; got {paths!r}")
    if not isinstance(seed, (int, np.integer)) or isinstance(seed, bool) or seed < 0:
        raise ParameterError(f"seed must be a non-negative integer; got {seed!r}")


def _record_plan(o: SimulateOptions, scenario: Scenario, paths: int, nsamp: int, dt: float,
                 notes: list) -> tuple[int, int]:  # fmt: skip
    """``(record_every, recorded paths)``: every k-th sample of the first paths is kept (all paths with
    ``record_all``), at most :data:`_RECORD_PER_PATH` per path unless asked; appends the note saying so."""
    every = max(1, math.ceil(nsamp / _RECORD_PER_PATH)) if o.record_every is None else o.record_every
    if not isinstance(every, int) or every < 1:
        raise ParameterError(f"record_every must be a positive integer; got {every!r}")
    nrec_paths = (
        paths
        if o.record_all
        else min(paths, scenario.paths if o.record_paths is None else int(o.record_paths))
    )
    if nrec_paths and every > 1:
        notes.append(f"trajectories recorded every {every} samples (dt {every * dt:g}), at most "
                     f"{_RECORD_PER_PATH} per path; the metrics use every sample; record_every=1 keeps all")  # fmt: skip
    return every, nrec_paths


def _run_notes(prep: Prepared, exact: bool) -> list[str]:
    """What the run says about its engine: the compiler's notes, a capped allowance, the fast mode."""
    notes = list(prep.notes)
    if prep.allowances.capped:
        notes.append(prep.allowances.why)
    if not exact:
        notes.append("fast mode: fused multiply-adds and a vector math library; equal to the exact mode within "
                     "the tolerance of docs/simulation.md, not bit for bit")  # fmt: skip
    return notes


class _Ran(NamedTuple):
    """What the paths of a run gave (:func:`_run_chunks`), with the engine and thresholds they ran at."""

    prep: Prepared
    thresholds: np.ndarray
    detection: list
    acc: np.ndarray
    div: np.ndarray
    mon: np.ndarray
    pm: np.ndarray
    rec: np.ndarray | None


def _calibrated_run(design: Design, plant: Plant, scenario: Scenario, prep: Prepared, o: SimulateOptions,
                    paths: int, seed: int, rate: float, calibration, every: int, dt: float, nsteps: int) -> _Ran:  # fmt: skip
    """The detection thresholds (``calibration``, or calibrated on fault-free paths ``paths, paths + 1, ...`` of
    the same seed, after the run's own), then the run's paths at them, under one progress bar."""
    if o.detect and not (math.isfinite(rate) and rate > 0):
        raise ParameterError(
            f"false_alarm_rate must be a positive number of alarms per time unit; got {o.false_alarm_rate!r}"
        )
    # all paths recorded (--save) in-process: the chunks record as they run; else the examples run again after
    every_all = every if (o.record_all and o.scheduler is None) else 0
    ncal = 0
    if o.detect and plant.lf and calibration is None:
        from ._calibrate import block_samples
        from ._detect import calibration_paths as n_for

        ncal = n_for(
            rate, block_samples(prep.allowances.tau, nsteps * dt, dt) * dt, nsteps, given=o.calibration_paths
        )
    bar = tqdm(total=paths + 2 * ncal, disable=not o.progress, delay=1.0, file=sys.stderr, unit=" paths",
               desc=f"simulate {plant.name}")  # fmt: skip
    try:
        cal = calibration
        if ncal:
            cal = calibrate_detection(design, plant, scenario, paths=paths, seed=seed, false_alarm_rate=rate,
                                      threads=o.threads, prepared=prep, bar=bar, chunk=o.chunk,
                                      scheduler=o.scheduler, calibration_paths=o.calibration_paths)  # fmt: skip
        use = o.detect and cal is not None
        thresholds = cal.thresholds if use else np.full(plant.lf, np.inf)
        detection = [dict(e) for e in cal.entries] if use else []
        prep_run = prep.with_thresholds(thresholds, cal.segments if use else ())
        out = _run_chunks(prep_run, plant, paths, seed, 0, o.chunk, o.threads, o.scheduler, every_all, bar)
    finally:
        bar.close()
    return _Ran(prep_run, thresholds, detection, *out)


def _diverged(div: np.ndarray, plant: Plant, scenario: Scenario, dt: float, path0: int) -> None:
    bad = np.flatnonzero(div >= 0)
    if len(bad):
        p0 = int(bad[np.argmin(div[bad])])
        raise SimulationError(
            f"{plant.name}: path {path0 + p0} diverged at t = {div[p0] * dt:.6g} (a state NaN/Inf or |x| > "
            f"{scenario.divergence_bound:g}); the closed loop is unstable for this design and step: check the "
            "design's certificates, lower dt, or shorten the fault"
        )
