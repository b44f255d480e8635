"""A plant's fingerprint: one SHA-256 per part of its equations, written into every design document
(``plant_hash``) so that a design is not simulated or turned into C against a plant edited since.

Each expression is hashed as its instruction tape (:mod:`._tape`: operations and constants printed to
full precision, the symbols by position, not by name), so the hash is the same across runs and
machines and changes with any coefficient; numbers are hashed through ``repr`` of floats.
"""

from __future__ import annotations

import hashlib
import json

import numpy as np

from ._record import Plant
from ._tape import write_tape

__all__ = []  # public: docs/api.md

#: the parts hashed, and how a message names each
PARTS = {
    "drift": "the drift (its equations or coefficients)",
    "diffusion": "the diffusion",
    "outputs": "the outputs (C, Df)",
    "region": "the region",
    "reference": "the reference (u_ref, x_ref, the operating inputs)",
    "limits": "the input limits",
    "sizes": "the numbers of states, inputs, unknown inputs, faults or outputs",
}


def _numbers(a) -> list | None:
    if a is None:
        return None
    return [repr(float(v)) for v in np.asarray(a, dtype=float).ravel()] + [list(np.shape(a))]


def _sha(obj) -> str:
    return hashlib.sha256(json.dumps(obj, sort_keys=True, separators=(",", ":")).encode()).hexdigest()


def plant_fingerprint(plant: Plant) -> dict[str, str]:
    """``{part: sha256 hex}`` for each part of :data:`PARTS`."""
    tape = lambda fn: {k: v for k, v in write_tape(fn).items() if k not in ("input_names", "output_names")}  # noqa: E731
    return {
        "drift": _sha(tape(plant.drift_function())),
        "diffusion": _sha(tape(plant.diffusion_function())),
        "outputs": _sha([_numbers(plant.C), _numbers(plant.Df)]),
        "region": _sha([_numbers(plant.region_lo), _numbers(plant.region_hi)]),
        "reference": _sha([_numbers(plant.u_ref), _numbers(plant.x_ref), _numbers(plant.u_operating)]),
        "limits": _sha(_numbers(plant.input_limits)),
        "sizes": _sha([plant.n, plant.m, plant.ld, plant.lf, plant.p, plant.d2.numel()]),
    }


def changed_parts(recorded: dict, plant: Plant) -> list[str]:
    """The parts of :data:`PARTS` whose hash in ``recorded`` differs from ``plant``'s (a part the record
    does not hold is not compared)."""
    now = plant_fingerprint(plant)
    return [k for k in PARTS if k in recorded and recorded[k] != now[k]]
