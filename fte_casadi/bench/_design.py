"""Speed of the design against the 0.1 design, measured in the same process.

The 0.1 design is a baseline, not part of the package: it lives in the source repository
(``baselines/design_01.py``), beside the package, and is loaded from there when ``fte bench`` runs from a
checkout (or an editable install); from a wheel the design's own times are measured and the baseline is said
not run. Takes T-S models (the caller derives them).
"""

from __future__ import annotations

import importlib.util
import sys
import time
from pathlib import Path

import numpy as np

from fte_casadi._text import shorten
from fte_casadi.design import design
from fte_casadi.errors import FteError

__all__ = ["bench_design"]

#: where the 0.1 design is, in a source checkout: beside the package, not in it
DESIGN_01 = Path(__file__).resolve().parents[2] / "baselines" / "design_01.py"
#: the name the 0.1 design is loaded under
BASELINE_MODULE = "fte_baseline_design_01"
#: what ``fte bench`` says of the 0.1 design where it is not there (a wheel)
NOT_RUN_01 = "not run: the 0.1 design is in the source repository (baselines/design_01.py), not in the wheel"


def design_01_baseline(path: Path = DESIGN_01):
    """``design_01(ts)``, the 0.1 design, loaded from the source checkout's ``path``; None where it is not there."""
    if not path.is_file():
        return None
    module = sys.modules.get(BASELINE_MODULE)
    if module is None:
        spec = importlib.util.spec_from_file_location(BASELINE_MODULE, path)
        module = importlib.util.module_from_spec(spec)
        sys.modules[BASELINE_MODULE] = module  # its dataclasses look their module up there
        spec.loader.exec_module(module)
    return module.design_01


def _best(fn, repeats: int) -> tuple[float, object]:
    best, out = np.inf, None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def bench_design(ts, *, sample_time: float | None = None, repeats: int = 3, repeats_01: int = 1) -> dict:
    """Wall time of :func:`~fte_casadi.design.design` (Clarabel, then SCS; certificates included,
    best of ``repeats``) and of the 0.1 design (Clarabel; ``{"not_run": why}`` without a source checkout), and
    their ratio; plus the largest relative difference between the Clarabel and SCS designs (K, L1, N)."""
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
    design_01 = design_01_baseline()
    try:
        if design_01 is None:
            out["design_0.1"] = {"not_run": NOT_RUN_01}
        else:
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
