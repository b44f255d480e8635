"""What a window measures with nothing carried into it: the cause of a ratio above 1 where tolerant control
applied nothing.

A window's ``ftc_true_ratio`` compares the run with tolerant control against the run without it over the window
(``||C x_FTC - C x_free|| / ||C x_noFTC - C x_free||``). Where tolerant control adds nothing to ``u`` in the window
(``ftc_compensation_rms`` zero: a sensor fault's window, the gate shut), the two runs differ there only by the
states they entered it with: each carries the tail of the earlier fault windows. Its ratio then says how the two
tails combine with this window's own fault, not what tolerant control did in it. :func:`carry_free` measures the
window once more with its own fault alone (the scenario's other fault profiles removed, the same paths, the same
seed), so that nothing is carried in:

    carry_free_ratio = ||C x_FTC,alone - C x_free|| / ||C x_noFTC - C x_free||   (over the window)

is the ratio a tolerant control that left no tail at all would measure against the same run without it. Above
1, the run without tolerant control gains from its own tail (the earlier fault's effect, left uncompensated,
partly cancels this window's): no compensation that removes the earlier faults' effects can do better than none
in this window, on this scenario. At most 1, the difference is tolerant control's own tail.
"""

from __future__ import annotations

import dataclasses
import math

from ._options import SimulateOptions

__all__ = ["carry_free"]


def carry_free(metrics: dict, design, plant, scenario, *, paths: int, seed: int,
               options: SimulateOptions | None = None) -> dict:  # fmt: skip
    """Fill ``carry_free_ratio`` (and ``carry_free_ratio_per_output``) of each window of ``metrics`` (the
    metrics document of ``simulate(design, plant, scenario, paths=paths, seed=seed, options=options)``) whose
    FTC true ratio, or an output's, is above 1 while tolerant control applied nothing in it, and which an earlier fault window
    precedes (module docstring): one more Monte Carlo run per such window, of its own fault alone, without
    detection or records. Returns ``metrics``, changed in place; the other windows get no such key (a window's
    null figure must say why: these are absent where not measured)."""
    from ._engine import simulate

    opts = dataclasses.replace(options or SimulateOptions(), progress=False, detect=False, record_paths=0,
                               record_all=False)  # fmt: skip
    for w in metrics.get("windows") or []:
        own = _qualifies(w, scenario)
        if own is None:
            continue
        alone = dataclasses.replace(scenario, faults=(own,))
        sub = simulate(design, plant, alone, paths=paths, seed=seed, options=opts).metrics
        sw = next((x for x in sub.get("windows") or [] if x["fault"] == w["fault"] and x["start"] == w["start"]),
                  None)  # fmt: skip
        if sw is None:
            continue
        a, b = sw["ftc_true_rms_per_output"]["ftc"], w["ftc_true_rms_per_output"]["no_ftc"]
        if any(v is None for v in (*a, *b)):
            continue
        den = math.fsum(v * v for v in b)
        if den > 0 and all(y > 0 for y in b):
            w["carry_free_ratio"] = math.sqrt(math.fsum(v * v for v in a) / den)
            w["carry_free_ratio_per_output"] = [x / y for x, y in zip(a, b)]
    return metrics


def _qualifies(w: dict, scenario):
    """The fault profile of window ``w`` where its ratio or an output's is above 1, tolerant control applied nothing in it and an
    earlier fault window precedes it; else None."""
    from ..verdicts import WORSE_THAN_NONE, applied_nothing

    rs = [w.get("ftc_true_ratio"), *(w.get("ftc_true_ratio_per_output") or [])]
    if not any(r is not None and r > WORSE_THAN_NONE for r in rs) or not applied_nothing(w):
        return None
    mine = [fp for fp in scenario.faults if fp.fault == w["fault"] and fp.start == w["start"]]
    if len(mine) != 1 or not any(fp.start < w["start"] for fp in scenario.faults if fp is not mine[0]):
        return None
    return mine[0]
