"""The Monte Carlo on the workers of a dask.distributed cluster (``simulate(..., scheduler=ADDRESS)``).

The paths are split into chunks; each chunk is a task that a worker runs with the same compiled
engine as an in-process run. The design and the scenario travel as their documents
(``Design.to_json()``, ``Scenario.to_dict()``), the plant as CasADi's serialisation of its symbolic
equations (so a plant written in a user's file needs no copy of that file on the workers); each
worker process builds and compiles the
engine once (an in-process cache on top of the on-disk cache of compiled engines) and sends back
only the chunk's per-path metric sums and divergence marks. A chunk is a pure function of
(seed, its paths), so a task that is run again — after a worker is lost, the scheduler reschedules
it — returns the same numbers, and the metrics are those of an in-process run.
dask.distributed is an optional extra: ``pip install 'fte_casadi[dask]'``.
"""

from __future__ import annotations

import functools
import json
import pickle
from collections.abc import Callable, Iterator

import numpy as np

from ..errors import MissingDependencyError, SimulationError

__all__ = ["run_on_cluster", "chunk_task", "client_for", "plant_bytes"]


def _require():
    try:
        import distributed
    except ImportError:
        raise MissingDependencyError(
            "running on a cluster needs dask.distributed: pip install 'fte_casadi[dask]'"
        ) from None
    return distributed


def client_for(address: str, timeout: float = 10.0):
    """A client of the scheduler at ``address``, or a clear error."""
    distributed = _require()
    try:
        return distributed.Client(address, timeout=timeout, set_as_default=False)
    except (OSError, TimeoutError) as exc:
        raise SimulationError(
            f"cannot reach the dask scheduler at {address!r} ({exc}); start one (`dask scheduler`, then "
            "`dask worker ADDRESS`) or leave out --scheduler to run in this process"
        ) from None


def plant_bytes(plant) -> bytes:
    """The plant as bytes (CasADi's pickling of its SX expressions)."""
    import casadi as ca

    with ca.global_pickle_context():
        return pickle.dumps(plant)


@functools.lru_cache(maxsize=8)
def _prepared(design_json: str, plant_blob: bytes, scenario_json: str, dt: float, scales_json: str):
    """The engine of a run, built once per worker process and run description."""
    import casadi as ca

    from ..design.record import Design
    from .engine import Prepared
    from .scenario import Scenario

    design = Design.from_dict(json.loads(design_json), source="design sent to a worker")
    with ca.global_unpickle_context():
        plant = pickle.loads(plant_blob)
    scenario = Scenario.from_dict(json.loads(scenario_json))
    nsteps = int(round(scenario.T / dt))
    return Prepared(design, plant, scenario, dt, nsteps, json.loads(scales_json))


def chunk_task(design_json: str, plant_blob: bytes, scenario_json: str, dt: float, scales_json: str, seed: int,
               path0: int, count: int) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """One chunk on a worker: the per-path metric sums and divergence marks of ``path0 .. path0 + count - 1``."""
    from .engine import run_paths

    prep = _prepared(design_json, plant_blob, scenario_json, float(dt), scales_json)
    acc, div, _ = run_paths(prep, path0, count, seed)
    return acc, div


def _threads(client) -> int:
    """Threads of the cluster's workers (at least 1)."""
    try:
        workers = client.scheduler_info().get("workers", {})
    except (OSError, TimeoutError):
        return 1
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


def run_on_cluster(scheduler, design, plant, scenario, dt: float, scales: dict, seed: int, paths: int,
                   chunk: int | None, on_done: Callable[[int], None] = lambda k: None, task=chunk_task,
                   ) -> Iterator[tuple[int, tuple[np.ndarray, np.ndarray]]]:  # fmt: skip
    """Submit the chunks to the cluster and yield ``(path0, (acc, div))`` in path order.

    ``scheduler``: an address (a client is opened and closed here) or a ``distributed.Client``.
    ``chunk``: paths per task; ``None``: about four tasks per worker thread (:func:`.engine.auto_chunk`)."""
    from .engine import auto_chunk

    _require()
    own = isinstance(scheduler, str)
    client = client_for(scheduler) if own else scheduler
    futs: list = []
    try:
        chunk = chunk or auto_chunk(paths, _threads(client))
        args = (design.to_json(), plant_bytes(plant), json.dumps(scenario.to_dict()), float(dt),
                json.dumps(scales, sort_keys=True), int(seed))  # fmt: skip
        starts = list(range(0, paths, chunk))
        # every chunk is submitted at once (the workers run them in parallel); results come back in path order
        futs = [client.submit(task, *args, a, min(chunk, paths - a), pure=False, retries=2) for a in starts]
        for a, fut in zip(starts, futs):
            try:
                out = fut.result()
            except Exception as exc:  # noqa: BLE001 - a worker's error comes back as any exception
                raise SimulationError(f"a cluster task failed ({type(exc).__name__}: {exc})") from None
            on_done(len(out[1]))
            yield a, out
    finally:
        if own:
            client.close()  # cancels what is left
        else:
            client.cancel([f for f in futs if not f.done()])
