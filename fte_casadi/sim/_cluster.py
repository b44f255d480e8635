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

import json
import pickle
from collections.abc import Callable, Iterator

from ..errors import MissingDependencyError, SimulationError
from ._vector import auto_chunk

__all__ = []  # public: docs/api.md


def _require():
    try:
        import distributed
    except ImportError:
        raise MissingDependencyError(
            "running on a cluster needs dask.distributed: pip install 'fte_casadi[dask]'"
        ) from None
    return distributed


#: seconds a client waits for the scheduler (distributed retries a refused connection until then: one starting up)
CONNECT_TIMEOUT = 10.0


def client_for(address: str, timeout: float | None = None):
    """A client of the scheduler at ``address`` (waiting up to ``timeout``, default :data:`CONNECT_TIMEOUT`
    seconds), or a clear error."""
    distributed = _require()
    try:
        return distributed.Client(
            address, timeout=CONNECT_TIMEOUT if timeout is None else timeout, set_as_default=False
        )
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


def plant_from_bytes(blob: bytes):
    """The plant of :func:`plant_bytes`."""
    import casadi as ca

    with ca.global_unpickle_context():
        return pickle.loads(blob)


def _threads(client) -> int:
    """Threads of the cluster's workers (at least 1)."""
    try:
        workers = client.scheduler_info().get("workers", {})
    except (OSError, TimeoutError):
        return 1
    return max(1, sum(int(w.get("nthreads", 1)) for w in workers.values()))


def run_on_cluster(scheduler, design, plant, scenario, dt: float, scales: dict, seed: int, paths: int,
                   chunk: int | None, task: Callable, on_done: Callable[[int], None] = lambda k: None,
                   path0: int = 0) -> Iterator[tuple[int, tuple]]:  # fmt: skip
    """Submit the chunks of paths ``path0 .. path0 + paths - 1`` to the cluster and yield ``(a, task's
    result)`` in path order, ``a`` the chunk's first path relative to ``path0``.

    ``scheduler``: an address (a client is opened and closed here) or a ``distributed.Client``.
    ``chunk``: paths per task; ``None``: about four tasks per worker thread (:func:`._engine.auto_chunk`)."""
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
        futs = [
            client.submit(task, *args, path0 + a, min(chunk, paths - a), pure=False, retries=2)
            for a in starts
        ]
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
