"""Speed of the design against the 0.1 design (:mod:`._design_01`), measured in the same process.

Takes T-S models (the caller derives them).
"""

from __future__ import annotations

import time

import numpy as np

from fte_casadi._text import shorten
from fte_casadi.design._api import design
from fte_casadi.errors import FteError

from ._design_01 import design_01

__all__ = ["bench_design"]


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_design(ts, *, sample_time: float | None = None, repeats: int = 3, repeats_01: int = 1) -> dict:
    """Wall time of :func:`~fte_casadi.design.design` (Clarabel, then SCS; certificates included,
    best of ``repeats``) and of the 0.1 design (Clarabel), and their ratio; plus the largest relative
    difference between the Clarabel and SCS designs (K, L1, N)."""
    out: dict = {}
    designs = {}
    for solver in ("CLARABEL", "SCS"):
        try:
            wall, d = _best(
                lambda s=solver: design(ts, solver=s, sample_time=sample_time),
                repeats if solver == "CLARABEL" else 1,
            )
            designs[solver] = d
            out[solver] = {
                "wall_s": wall,
                "certified": d.certified,
                "solves": d.solves,
                "solver_s": d.timings["solver_s"],
            }
        except FteError as exc:
            out[solver] = {"error": shorten(exc, 200)}
    try:
        wall, old = _best(lambda: design_01(ts), repeats_01)
        out["design_0.1"] = {
            "wall_s": wall,
            "certified": not any(v >= 0 for v in old["checks"]["lmi_max_eig"].values()),
        }
    except FteError as exc:
        out["design_0.1"] = {"error": shorten(exc, 200)}
    if "wall_s" in out["CLARABEL"] and "wall_s" in out["design_0.1"]:
        out["speedup_vs_0.1"] = out["design_0.1"]["wall_s"] / out["CLARABEL"]["wall_s"]
    if len(designs) == 2:
        a, b = designs["CLARABEL"], designs["SCS"]
        pairs = list(zip(a.K, b.K)) + list(zip(a.L1, b.L1)) + [(a.N, b.N)]
        out["max_rel_diff_clarabel_scs"] = max(
            float(np.max(np.abs(x - y)) / max(np.max(np.abs(x)), 1e-300)) for x, y in pairs
        )
    return out
