"""One member of the design-growth benchmark (:mod:`._growth`), measured in a process of its own so that
its peak memory is its own:

    python -m fte_casadi.bench._growth_member N Q OUT.json

writes the member's row (JSON) to OUT.json: the chain of N states and Q couplings designed at its defaults,
then once more at the parameters found.
"""

from __future__ import annotations

import json
import resource
import sys
import time


def measure(n: int, q: int) -> dict:
    """The row of the chain ``(n, q)``: rules, wall time at the defaults (with the parameter search), the
    time of one design at the parameters found, and the peak resident memory of this process (MB)."""
    from fte_casadi._text import shorten
    from fte_casadi.bench._plant_chain import chain
    from fte_casadi.design import design
    from fte_casadi.errors import FteError
    from fte_casadi.ts import derive

    ts = derive(chain(n, q), fidelity_samples=500)
    out = {"n": n, "q": q, "rules": ts.r}
    t0 = time.perf_counter()
    try:
        d = design(ts, sample_time=1e-3)
        out.update(certified=d.certified, sigma=d.params.sigma, gamma=d.params.gamma,
                   chosen=sorted(d.params_chosen or {}), solver_s=d.timings["solver_s"])  # fmt: skip
        t1 = time.perf_counter()
        design(ts, sample_time=1e-3, sigma=d.params.sigma, gamma=d.params.gamma)
        out["one_design_s"] = time.perf_counter() - t1
    except FteError as exc:
        out["error"] = shorten(exc, 300)
    out["wall_s"] = time.perf_counter() - t0 - out.get("one_design_s", 0.0)
    out["peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return out


if __name__ == "__main__":
    from fte_casadi._atomic import atomic_write_text

    atomic_write_text(sys.argv[3], json.dumps(measure(int(sys.argv[1]), int(sys.argv[2]))))
