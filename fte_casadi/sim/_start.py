"""The observer's start: ``z_0 = xbar0 - H y_0`` from the first measurement as read (docs/method.md, "The start"),
as the simulation starts it and the generated C's ``init_from_y`` does."""

from __future__ import annotations

import numpy as np

__all__ = []  # internal: the engine's initial states and `fte codegen --check`


def observer_start(design, plant, scenario, x0: np.ndarray, v0=None, a0=None) -> np.ndarray | None:
    """The observer's start ``z_0`` per path, as the simulation starts it and the generated C's
    ``init_from_y`` does: from the first measurement, ``z_0 = xbar0 - H y_0``, so that ``xbarhat_0 = xbar0``,
    ``xbar0 = [x0 nominal; 0]`` the scenario's nominal initial state (the plant's without one). ``y_0 = C x0 +
    v0 + Df a0``: ``x0`` the plant's initial states (a row per path), ``v0`` the first sample's measurement
    noise (rows; None: none), ``a0`` the faults' additive part at the first sample (None: none). None where the
    scenario starts the observer at ``z = 0`` (``observer_init``)."""
    if scenario.observer_init != "nominal":
        return None
    x0n = np.asarray(plant.x0 if scenario.x0 is None else scenario.x0, dtype=float)
    xb_nom = np.concatenate([x0n, np.zeros(int(design.dims.nbar) - plant.n)])
    x0 = np.atleast_2d(np.asarray(x0, dtype=float))
    # a single row would take another BLAS route (a matrix-vector product, rounded differently): a path
    # alone in its chunk is computed as one of two rows, so its numbers do not depend on the chunk
    two = (lambda a: np.vstack([a, a])) if len(x0) == 1 else (lambda a: a)  # noqa: E731
    y0 = two(x0) @ np.asarray(plant.C).T
    if v0 is not None:
        y0 = y0 + two(np.atleast_2d(v0))
    Df = np.asarray(plant.Df, dtype=float)
    if a0 is not None and np.any(Df @ np.asarray(a0, dtype=float) != 0):
        y0 = y0 + Df @ np.asarray(a0, dtype=float)
    return (xb_nom - y0 @ np.asarray(design.H).T)[: len(x0)]
