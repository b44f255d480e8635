"""The settings of a Monte Carlo run (:class:`SimulateOptions`), in the style of the design's
:class:`~fte_casadi.design.DesignOptions`: one frozen record, checked once on construction, changed with
:meth:`SimulateOptions.replace`.

:func:`~fte_casadi.sim.simulate` takes it as ``options=`` beside its keyword arguments (which keep working:
a keyword given with a value other than its default changes the record's field,
:func:`fte_casadi._keywords.with_keywords`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..errors import ParameterError, SimulationError

__all__ = ["SimulateOptions"]  # public: docs/api.md

#: the factors a sweep may vary, and their defaults
SCALES = {"fault_scale": 1.0, "noise_scale": 1.0, "d_scale": 1.0, "measurement_noise_scale": 1.0}


def check_scales(scales: Mapping | None) -> dict:
    """The factors with their defaults; each a known factor and a non-negative finite number."""
    out = dict(SCALES)
    for k, v in (scales or {}).items():
        if k not in SCALES:
            raise ParameterError(f"unknown factor {k!r}; the factors are {sorted(SCALES)}")
        try:
            fv = float(v)
        except (TypeError, ValueError):
            raise ParameterError(f"{k} must be a number; got {v!r}") from None
        if not (math.isfinite(fv) and fv >= 0):
            raise ParameterError(f"{k} must be a non-negative finite number; got {v!r}")
        out[k] = fv
    return out


def _count(v, least: int) -> bool:
    """Is ``v`` an integer (not a bool) of at least ``least``?"""
    return isinstance(v, (int, np.integer)) and not isinstance(v, bool) and v >= least


def _flag(v) -> bool:
    return isinstance(v, (bool, np.bool_))


@dataclass(frozen=True)
class SimulateOptions:
    """How :func:`~fte_casadi.sim.simulate` runs its Monte Carlo, beyond the design, the plant, the scenario,
    the number of paths and the seed.

    Checked once, on construction (:class:`~fte_casadi.errors.ParameterError` naming the field; a bad ``dt``
    a :class:`~fte_casadi.errors.SimulationError`, as before); what needs the design or the scenario (``dt``
    against the design's ``ts_max``, ``measurement_noise_scale`` without measurement noise) is checked by the
    run. Change one with :meth:`replace`.

    Parameters
    ----------
    dt : float, optional
        Euler-Maruyama step and controller sample time; default the design's sample time (else the scenario's),
        lowered to a round value below ``ts_max / 2`` when the design cannot run at it (said in the result's
        ``notes``). An explicit ``dt`` above the design's ``checks["ts_max"]`` is refused by the run.
    progress : bool
        A progress bar on stderr when the run lasts more than about a second.
    record_paths, record_all
        Full trajectories are kept for the first ``record_paths`` paths (>= 0; default: the scenario's path
        count, the paper's figures), or for all with ``record_all`` (memory grows with paths).
    record_every : int, optional
        Keep every k-th sample of the recorded paths (>= 1; default: at most ~2e4 samples per path).
    threads : int, optional
        Threads running chunks of ``chunk`` paths (>= 1; default: the CPU count, at most 8).
    chunk : int, optional
        Paths per call of the compiled engine (>= 1; default: about four chunks per thread, or per thread of the
        cluster, whole lane vectors, at most :data:`~fte_casadi.sim._vector.CHUNK`). The metrics do not depend on it.
    scheduler : str or distributed.Client, optional
        Address of a dask.distributed scheduler (or a client of one): the chunks run on its workers.
    scales : dict, optional
        ``fault_scale``, ``noise_scale``, ``d_scale``, ``measurement_noise_scale`` (each >= 0, default 1):
        multiply every fault's magnitude, the diffusion, the unknown input, the measurement noise.
    exact : bool
        True (default): IEEE semantics, every operation rounded as in CasADi's own C (bit-equal to the per-path
        engine). False: the fast mode (docs/simulation.md): the same engine compiled with fused multiply-adds and
        glibc's vector math library; equal to the exact mode within the documented tolerance, still the same
        numbers for any chunk size, thread count or cluster. The metrics document records the mode (``exact``).
    detect : bool
        True (default): detection thresholds per fault, calibrated on independent fault-free paths before the
        run, and the run's detection delays and false-alarm rates. False: none (the document's ``detection`` is
        empty and the delays null).
    false_alarm_rate : float, optional
        False alarms per unit of the plant's time the thresholds are set for (positive; default: one per hour of
        operation, in the plant's time unit).
    calibration_paths : int, optional
        Fault-free paths the thresholds are calibrated on (>= 2; default: enough for the rate asked, within a
        budget).

    Examples
    --------
    >>> o = SimulateOptions(dt=1e-3, detect=False)
    >>> o.replace(exact=False).exact, o.dt
    (False, 0.001)
    """

    dt: float | None = None
    progress: bool = True
    record_paths: int | None = None
    record_all: bool = False
    record_every: int | None = None
    threads: int | None = None
    chunk: int | None = None
    scheduler: Any = None
    scales: Mapping | None = None
    exact: bool = True
    detect: bool = True
    false_alarm_rate: float | None = None
    calibration_paths: int | None = None

    def __post_init__(self):
        dt = self.dt
        if dt is not None and not (
            isinstance(dt, (int, float)) and not isinstance(dt, bool) and math.isfinite(dt) and dt > 0
        ):
            raise SimulationError(f"time step dt must be a positive number; got {dt!r}")
        for k in ("progress", "record_all", "exact", "detect"):
            if not _flag(getattr(self, k)):
                raise ParameterError(f"{k} must be True or False; got {getattr(self, k)!r}")
        if self.record_paths is not None and not _count(self.record_paths, 0):
            raise ParameterError(
                f"record_paths (the paths whose trajectories are kept) must be an integer >= 0; got {self.record_paths!r}"
            )
        if self.record_every is not None and not (
            isinstance(self.record_every, int) and self.record_every >= 1
        ):
            raise ParameterError(f"record_every must be a positive integer; got {self.record_every!r}")
        if self.threads is not None and not _count(self.threads, 1):
            raise ParameterError(
                f"threads must be a positive integer (or None: the CPU count); got {self.threads!r}"
            )
        chunk = self.chunk
        if chunk is not None and (not isinstance(chunk, int) or isinstance(chunk, bool) or chunk < 1):
            raise ParameterError(f"chunk must be a positive integer; got {chunk!r}")
        if self.scales is not None:
            if not isinstance(self.scales, Mapping):
                raise ParameterError(
                    f"scales must be a mapping of factor names to numbers (e.g. {{'fault_scale': 2}}); got {self.scales!r}"
                )
            try:
                check_scales(self.scales)
            except ParameterError as exc:
                raise ParameterError(f"scales: {exc}") from None
        rate = self.false_alarm_rate
        if rate is not None and not (
            isinstance(rate, (int, float, np.floating)) and not isinstance(rate, bool) and math.isfinite(rate)
            and rate > 0
        ):  # fmt: skip
            raise ParameterError(
                f"false_alarm_rate must be a positive number of alarms per time unit; got {rate!r}"
            )
        cp = self.calibration_paths
        if cp is not None and not _count(cp, 2):
            raise ParameterError(f"calibration_paths must be an integer of at least 2; got {cp!r}")

    def replace(self, **changes) -> SimulateOptions:
        """This record with ``changes`` (:func:`dataclasses.replace`)."""
        return dataclasses.replace(self, **changes)
