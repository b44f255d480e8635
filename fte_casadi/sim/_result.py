"""Simulation result objects and their ``.npz`` file (scenario and design embedded)."""

from __future__ import annotations

import json
import os
import zipfile
import zlib
from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np

from .._atomic import atomic_write
from ..design import Design
from ..errors import SimulationError
from ._scenario import Scenario

__all__ = ["RunData", "SimulationResult", "save_result", "load_result"]  # public: docs/api.md

#: the three runs per path, in order
RUNS = ("free", "no_ftc", "ftc")
RUN_TITLES = {
    "free": "fault-free",
    "no_ftc": "faulty, no tolerant control",
    "ftc": "faulty, tolerant control",
}
_SIGNALS = ("x", "xbarhat", "f", "u", "y", "yc", "ucomp")
_FORMAT = 1


@dataclass(frozen=True)
class RunData:
    """One run over all paths; every array has shape ``(paths, samples, size)``.

    ``xbarhat = [xhat; fdothat; fhat]``; ``f`` the true faults; ``y`` the measurement;
    ``yc`` the reliable output (``y`` itself without tolerant control); ``ucomp`` the compensation the
    run's step applied: ``u`` less what the step without tolerant control gives at the same observer state and
    measurement (after saturation; zero in the run without tolerant control; None in a result saved before
    it was recorded).
    """

    x: np.ndarray
    xbarhat: np.ndarray
    f: np.ndarray
    u: np.ndarray
    y: np.ndarray
    yc: np.ndarray
    ucomp: np.ndarray | None = None

    @property
    def n(self) -> int:
        return self.x.shape[2]

    @property
    def lf(self) -> int:
        return self.f.shape[2]

    @property
    def xhat(self) -> np.ndarray:
        return self.xbarhat[:, :, : self.n]

    @property
    def fhat(self) -> np.ndarray:
        return self.xbarhat[:, :, self.n + self.lf :]


@dataclass(frozen=True)
class SimulationResult:
    """A Monte Carlo run: time, three runs (:data:`RUNS`), names, scenario and design."""

    plant: str
    t: np.ndarray
    dt: float
    T: float
    seed: int
    paths: int
    record_every: int
    free: RunData
    no_ftc: RunData
    ftc: RunData
    scenario: Scenario
    design: Design
    names: dict  # states, state_units, inputs, outputs, output_units, faults, fault_kinds, time_unit
    wall_s: float
    compiled: bool
    notes: tuple = ()
    #: the metrics document over all paths (streamed by the engine); None for a per-path run
    metrics: dict | None = None
    #: fault_scale, noise_scale, d_scale, measurement_noise_scale of the run
    scales: dict = field(default_factory=dict)
    #: the plant's region ``(lo, hi)`` per state (where the T-S model is exact); None if unknown
    region: tuple | None = None

    @property
    def recorded_paths(self) -> int:
        """Paths whose trajectories are kept (the first ones); ``paths`` may be many more."""
        return int(self.free.x.shape[0])

    def run(self, name: str) -> RunData:
        if name not in RUNS:
            raise SimulationError(f"unknown run {name!r}; the runs are {RUNS}")
        return getattr(self, name)


def save_result(result: SimulationResult, path: str | os.PathLike) -> Path:
    """Write ``result`` to a compressed ``.npz``; scenario and design are embedded as JSON.

    The file is written whole or not at all (:func:`fte_casadi._atomic.atomic_write`): an interrupted
    save leaves an earlier file at ``path`` as it was."""
    path = Path(path)
    arrays = {"t": result.t}
    for run in RUNS:
        rd = result.run(run)
        for sig in _SIGNALS:
            if getattr(rd, sig) is not None:
                arrays[f"{run}__{sig}"] = getattr(rd, sig)
    meta = {
        "format": _FORMAT,
        "plant": result.plant,
        "dt": result.dt,
        "T": result.T,
        "seed": result.seed,
        "paths": result.paths,
        "record_every": result.record_every,
        "names": result.names,
        "wall_s": result.wall_s,
        "compiled": result.compiled,
        "notes": list(result.notes),
        "metrics": result.metrics,
        "scales": result.scales,
        "region": None if result.region is None else [list(map(float, v)) for v in result.region],
    }
    arrays["meta"] = np.array(json.dumps(meta))
    arrays["scenario"] = np.array(result.scenario.to_json())
    arrays["design"] = np.array(result.design.to_json())
    try:
        # not compressed: the paths' noisy float64 samples deflate by ~19 % at 12 x the time (the manipulator's
        # 8 paths: 25.5 MB in 0.10 s against 20.6 MB in 1.2 s); np.load reads either
        atomic_write(path, lambda fh: np.savez(fh, **arrays))
    except OSError as exc:
        raise SimulationError(f"cannot write the result to {str(path)!r}: {exc.strerror or exc}") from None
    return path


def load_result(path: str | os.PathLike) -> SimulationResult:
    """Read a result written by :func:`save_result`."""
    path = Path(path)
    if not path.is_file():
        raise SimulationError(f"result file {str(path)!r} does not exist")
    try:
        with np.load(path, allow_pickle=False) as z:
            data = {k: z[k] for k in z.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile, zlib.error) as exc:
        raise SimulationError(
            f"result file {str(path)!r} is not a readable .npz: it is corrupt or truncated "
            f"({type(exc).__name__}: {exc}); write it again with fte simulate --save"
        ) from None
    try:
        meta = json.loads(str(data["meta"]))
        scenario = Scenario.from_dict(json.loads(str(data["scenario"])))
        design = Design.from_dict(json.loads(str(data["design"])), source=f"design embedded in {path}")
        runs = {run: RunData(**{sig: data[f"{run}__{sig}"] for sig in _SIGNALS if sig != "ucomp"},
                             ucomp=data.get(f"{run}__ucomp")) for run in RUNS}  # fmt: skip
    except (KeyError, ValueError, TypeError) as exc:
        raise SimulationError(f"result file {str(path)!r} is not an fte simulation result ({exc})") from None
    kw = {
        f.name: meta[f.name]
        for f in fields(SimulationResult)
        if f.name in meta and f.name not in ("notes", "scales", "region")
    }
    kw["region"] = None if meta.get("region") is None else tuple(np.asarray(v, float) for v in meta["region"])
    kw["scales"] = dict(meta.get("scales") or {})
    kw.pop("format", None)
    return SimulationResult(
        t=data["t"], scenario=scenario, design=design, notes=tuple(meta.get("notes", ())), **kw, **runs
    )
