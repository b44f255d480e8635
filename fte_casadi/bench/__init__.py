"""``fte bench``: speed of the design, the Monte Carlo engine and the generated C step, each against
baselines run in the same process. It sits above the layers it measures (it may import the
built-in plants; ``sim/`` and ``codegen/`` never do)."""

from __future__ import annotations

from collections.abc import Callable

from .cstep import bench_c_step as bench_c_step
from .design import bench_design as bench_design
from .mc import bench as bench_monte_carlo

__all__ = ["bench_c_step", "bench_design", "bench_monte_carlo", "run_all"]


def run_all(paths: int = 1000, log: Callable[[str], None] = lambda s: None) -> dict:
    """Everything ``fte bench`` reports, for the built-in plants."""
    from ..design import design as run_design
    from ..plants import BUILTIN, SCENARIOS
    from ..ts import derive

    out: dict = {"design": {}, "c_step": {}}
    designs = {}
    for name in BUILTIN:
        ts = derive(BUILTIN[name]())
        dt = SCENARIOS[name]().dt
        log(f"bench: design {name} (Clarabel, SCS, and the 0.1 formulation as baseline)")
        out["design"][name] = bench_design(ts, sample_time=dt)
        designs[name] = run_design(ts, variant="conditioned", plant_spec=name, sample_time=dt)
    log(
        f"bench: Monte Carlo, manipulator, {paths} paths x 3 runs: vectorised engine against the per-path engine"
    )
    out["monte_carlo"] = bench_monte_carlo(designs["manipulator"], BUILTIN["manipulator"](),
                                           SCENARIOS["manipulator"](), paths=paths)  # fmt: skip
    for name, d in designs.items():
        log(f"bench: generated C step of {name}")
        out["c_step"][name] = bench_c_step(d)
    return out
