"""The measurements the generated C accepts, as the simulation sees them: outside this range the C's step
returns 3 and stops, where the Python step of ``fte simulate`` runs on (:func:`accepted_measurements`)."""

from __future__ import annotations

import numpy as np

from ..design import Design

__all__ = []  # internal: the engine and the reference metrics read it


def accepted_measurements(design: Design, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """``(lo, hi)`` per output: the range of ``y`` the C that ``fte codegen`` generates for ``design`` at the
    sample time ``dt`` accepts (:func:`fte_casadi.codegen.output_range`, its step evaluated along the edges as
    the generator does; in double precision)."""
    from ..codegen import output_range
    from ..step import step_function

    fn = step_function(design, float(dt), tolerant=True, boundary_layer=design.params.boundary_layer)
    rng = output_range(design, fn, "double")
    return np.asarray(rng["lo"], dtype=float), np.asarray(rng["hi"], dtype=float)
