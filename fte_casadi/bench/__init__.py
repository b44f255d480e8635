"""``fte bench``: speed of the design, the Monte Carlo engine and the generated C step, each against
baselines run in the same process.

It ships with the package, so that ``fte bench`` runs from an installed wheel: the measurements and the
baselines it runs beside them (the per-path Monte Carlo engine, :mod:`._perpath`, also the tests'
reference; a hand-written C loop). The design formulation of 0.1, the design's baseline, is not in the
package: it lives in the source repository (``baselines/design_01.py``) and runs from a checkout
(:func:`._design.design_01_baseline`); from a wheel the design's times are reported without it. The Monte
Carlo comparison with sdeint needs the ``bench`` extra (``pip install 'fte_casadi[bench]'``). The numbers
measured are kept in docs/benchmarks.md.
"""

from __future__ import annotations

from collections.abc import Callable

from ._bound_weight import bound_weight_rows as bound_weight_rows  # fte bench --bound-weights; internal
from ._cstep import bench_c_step as bench_c_step
from ._design import bench_design as bench_design
from ._growth import bench_growth as bench_growth
from ._growth import growth_lines
from ._mc import bench as bench_monte_carlo
from ._noise import diffusion_scales as diffusion_scales  # fte bench --diffusion; internal

__all__ = ["PARTS", "bench_c_step", "bench_design", "bench_growth", "bench_monte_carlo", "run_all",
           "summary_lines", "fast_lines"]  # fmt: skip

#: the parts of ``fte bench``, in the order they run (``fte bench --only PART``)
PARTS = ("design", "growth", "monte-carlo", "c-step")


def run_all(paths: int = 1000, log: Callable[[str], None] = lambda s: None, only=None) -> dict:
    """Everything ``fte bench`` reports, for the built-in plants; ``only``: the :data:`PARTS` to run (all)."""
    from fte_casadi.design import design as run_design
    from fte_casadi.errors import ParameterError
    from fte_casadi.plants import BUILTIN, SCENARIOS
    from fte_casadi.ts import derive

    parts = set(only or PARTS)
    if parts - set(PARTS):
        raise ParameterError(
            f"unknown benchmark part(s) {sorted(parts - set(PARTS))}; choose from {list(PARTS)}"
        )
    out: dict = {}
    designs = {}
    need = {"manipulator"} if parts & {"monte-carlo"} else set()
    need |= set(BUILTIN) if parts & {"c-step"} else set()
    for name in BUILTIN:
        if "design" not in parts and name not in need:
            continue
        ts = derive(BUILTIN[name]())
        dt = SCENARIOS[name]().dt
        if "design" in parts and name in ("manipulator", "three-tank"):  # the 0.1 design's plants
            log(f"bench: design {name} (Clarabel, SCS, and the 0.1 design as baseline)")
            out.setdefault("design", {})[name] = bench_design(ts, sample_time=dt)
        if name in need:
            designs[name] = run_design(ts, variant="conditioned", plant_spec=name, sample_time=dt)
    if "growth" in parts:
        out["growth"] = bench_growth(log=log)
    if "monte-carlo" in parts:
        log(
            f"bench: Monte Carlo, manipulator, {paths} paths x 3 runs: vectorised engine against the per-path engine"
        )
        out["monte_carlo"] = bench_monte_carlo(designs["manipulator"], BUILTIN["manipulator"](),
                                               SCENARIOS["manipulator"](), paths=paths)  # fmt: skip
    if "c-step" in parts:
        out["c_step"] = {}
        for name, d in designs.items():
            log(f"bench: generated C step of {name}")
            out["c_step"][name] = bench_c_step(d)
    return out


def fast_lines(fm: dict, e: dict) -> list[str]:
    """The fast mode's lines of the summary: ``fm`` the ``fast_mode`` entry, ``e`` the exact engine's."""
    h = fm["one_thread_vs_hand_loop"]
    scalar = sorted(k for k, done in h["hand_path_loop_vectorised"].items() if not done)
    note = (
        [
            f"    GCC did not vectorise the hand loop's path loop on this CPU ({', '.join(scalar)}): those ratios are "
            "against scalar code, not against a vectorised baseline"
        ]  # fmt: skip
        if scalar
        else []
    )
    return note + [
        f"  fast mode (--fast-math): {fm['paths']} paths in {fm['wall_s']:.2f} s "
        f"({fm['path_steps_per_s'] / 1e6:.2f} M path-steps/s; exact mode {e['path_steps_per_s'] / 1e6:.2f} M: "
        f"{fm['speedup_vs_exact']:.2f}x)",
        f"  one thread, CPU time, best of {h['repeats']}: fast mode {h['fast_ns_per_path_step']:.1f} ns per path-step, "
        f"hand-vectorised C loop {h['hand_ns_per_path_step']:.1f} ns (same semantics: FMA, libmvec) -> "
        f"{h['ratio_fast_vs_hand']:.2f}x its speed; exact mode {h['exact_ns_per_path_step']:.1f} ns -> "
        f"{h['ratio_exact_vs_hand']:.2f}x",
        f"    the hand loop with -ffast-math too: {h['hand_fast_math_ns_per_path_step']:.1f} ns -> fast mode "
        f"{h['ratio_fast_vs_hand_fast_math']:.2f}x its speed (hand loop = engine to "
        f"{max(h['hand_max_rel_diff_final_state'].values()):.0e} relative)",
    ]


def summary_lines(out: dict) -> list[str]:
    """The text ``fte bench`` prints for the figures of :func:`run_all`."""
    lines = []
    if "design" in out:
        lines.append(
            "design (conditioned, wall time incl. certificates; baseline: the 0.1 design, same process):"
        )
    for name, row in out.get("design", {}).items():
        cells = []
        for key in ("CLARABEL", "SCS", "design_0.1"):
            v = row.get(key, {})
            cells.append(f"{key}: " + (f"{v['wall_s']:.3f} s" if "wall_s" in v else
                                       "not run (source checkout only)" if "not_run" in v else "failed"))  # fmt: skip
        extra = f", {row['speedup_vs_0.1']:.1f}x faster than 0.1" if "speedup_vs_0.1" in row else ""
        if "max_rel_diff_clarabel_scs" in row:
            extra += f", Clarabel and SCS designs equal to {row['max_rel_diff_clarabel_scs']:.1e}"
        lines.append(f"  {name:12s} " + ", ".join(cells) + extra)
    if "growth" in out:
        lines += growth_lines(out["growth"])
    if "monte_carlo" in out:
        lines += _monte_carlo_lines(out["monte_carlo"])
    if "c_step" in out:
        lines.append("generated C step (double, -O2):")
    for name, b in out.get("c_step", {}).items():
        lines.append(
            f"  {name:12s} {b.get('c_ns') or float('nan'):.1f} ns/step vs hand-written {b.get('hand_ns') or float('nan'):.1f} ns "
            f"(ratio {b.get('ratio') or float('nan'):.2f}); through CasADi from Python {b['casadi_us']:.1f} us; "
            f"state {b['state_bytes']} B, constants {b['const_bytes']} B"
        )
    return lines


def _monte_carlo_lines(mc: dict) -> list[str]:
    e, pp = mc["engine"], mc["per_path_engine"]
    lines = []
    lines.append(
        f"Monte Carlo ({mc['scenario']}): {e['paths']} paths in {e['wall_s']:.2f} s "
        f"({e['path_steps_per_s'] / 1e6:.2f} M path-steps/s; first call incl. compile {e['first_call_wall_s']:.2f} s)\n"
        f"  per-path engine: {pp['wall_s']:.2f} s ({pp['path_steps_per_s'] / 1e6:.2f} M path-steps/s) -> "
        f"vectorised engine is {mc['speedup_vs_per_path']:.1f}x faster\n"
        f"  {e['flops_per_path_step']} flops per path-step: {100 * e['fraction_of_peak']:.1f} % of the assumed peak "
        f"({e['peak_assumed']['cores']} cores x {e['peak_assumed']['ghz']:.2f} GHz x {e['peak_assumed']['doubles_per_vector']} "
        f"doubles x 2 FMA units x 2)\n"
        f"  one thread: {e['one_thread']['ns_per_path_step']:.1f} ns per path-step, "
        f"{e['one_thread']['ns_per_path_step_without_libm']:.1f} ns without its "
        f"{e['operations_per_path_step']['libm_calls']} scalar C library calls: "
        f"{100 * e['one_thread']['libm_share']:.0f} % of the time is in those calls\n"
        f"  sdeint itoEuler: {mc['sdeint_itoEuler']['path_steps_per_s']:.3g} path-steps/s -> engine is {mc['speedup_vs_sdeint']:.0f}x faster\n"
        f"  plain Python loop: {mc['python_loop']['path_steps_per_s']:.3g} path-steps/s -> engine is "
        f"{mc['speedup_vs_python_loop']:.0f}x faster (same trajectories to {mc['max_abs_diff_engine_vs_sdeint']:.1g})"
    )
    if "fast_mode" in mc:
        lines += fast_lines(mc["fast_mode"], e)
    return lines
