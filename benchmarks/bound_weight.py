"""What the fault-error bound's weight in step 5's objective does (docs/design.md): a built-in plant designed
at each weight, its certified bound, and the metrics of ``simulate(..., paths, seed=1)`` on its scenario.

    PYTHONPATH=. python benchmarks/bound_weight.py manipulator 0,0.3,1,3,10 20
"""

from __future__ import annotations

import json
import sys
import time

__all__ = ["run"]


def run(name: str, weights, paths: int = 20, seed: int = 1) -> list[dict]:
    from fte_casadi.design import design
    from fte_casadi.plants import BUILTIN, SCENARIOS
    from fte_casadi.sim import simulate
    from fte_casadi.ts import derive

    plant, scenario = BUILTIN[name](), SCENARIOS[name]()
    ts = derive(plant)
    rows = []
    for w in weights:
        t0 = time.perf_counter()
        d = design(ts, sample_time=scenario.dt, bound_weight=w)
        seconds = time.perf_counter() - t0
        fb = d.bounds.get("fault_error", {})
        m = simulate(d, plant, scenario, paths=paths, seed=seed, progress=False).metrics
        rows.append({
            "weight": w, "design_s": round(seconds, 2), "alpha": d.observer.alpha,
            "bound": max(fb["gains"].values()) if fb.get("holds") else None, "P_structure": fb.get("P_structure"),
            "bound_objective": [d.observer.extra.get("bound_objective_before"), d.observer.extra.get("bound_objective")],
            "fault_error": m["fault_rel_rms_error"], "false_alarm": m["false_alarm_rel_rms"],
            "ftc": [w_["ftc_deviation_ratio"] for w_ in m["windows"]],
        })  # fmt: skip
        print(json.dumps(rows[-1]), flush=True)
    return rows


if __name__ == "__main__":
    run(
        sys.argv[1], [float(w) for w in sys.argv[2].split(",")], int(sys.argv[3]) if len(sys.argv) > 3 else 20
    )
