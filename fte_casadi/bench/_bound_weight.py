"""What the fault-error bound's weight in step 5's objective does (docs/design.md): a built-in plant designed
at each weight, its certified bound, and the metrics of ``simulate(..., paths, seed=1)`` on its scenario.

    fte bench --bound-weights manipulator --weights 0,0.3,1,3,10 --paths 20 \
        --at '{"gamma": 2, "gamma1": 0.01, "sigma": 0.2, "delta": 1e-5, "epsilon": 1e-5}'

The optional ``--at`` replaces the plant's design defaults (above: Section 6.1's parameters, without
the tuned decay rate, kappa and bound weight the built-in manipulator now has).
"""

from __future__ import annotations

import time

__all__ = ["bound_weight_rows"]


def bound_weight_rows(
    name: str, weights, paths: int = 20, seed: int = 1, defaults: dict | None = None, on_row=None
) -> list[dict]:
    """One row per weight; ``on_row(row)``, when given, is called with each row as soon as it is measured
    (a design and a simulation per weight take a while)."""
    import dataclasses

    from fte_casadi.design import design
    from fte_casadi.plants import BUILTIN, SCENARIOS
    from fte_casadi.sim import simulate
    from fte_casadi.ts import derive

    plant, scenario = BUILTIN[name](), SCENARIOS[name]()
    if defaults is not None:
        plant = dataclasses.replace(plant, design_defaults=dict(defaults))
    ts = derive(plant)
    rows = []
    for w in weights:
        t0 = time.perf_counter()
        d = design(ts, sample_time=scenario.dt, bound_weight=w)
        seconds = time.perf_counter() - t0
        fb = d.bounds.get("fault_error", {})
        m = simulate(d, plant, scenario, paths=paths, seed=seed, progress=False, detect=False).metrics
        rows.append({
            "weight": w, "design_s": round(seconds, 2), "alpha": d.observer.alpha,
            "bound": max(fb["gains"].values()) if fb.get("holds") else None, "P_structure": fb.get("P_structure"),
            "bound_objective": [d.observer.bound_objective_unweighted, d.observer.bound_objective],
            "fault_error": m["fault_rel_rms_error"], "false_alarm": m["false_alarm_rel_rms"],
            "ftc": [w_.get("ftc_true_ratio") for w_ in m["windows"]],
        })  # fmt: skip
        if on_row is not None:
            on_row(rows[-1])
    return rows
