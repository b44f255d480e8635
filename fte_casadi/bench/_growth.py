"""How the design's time and memory grow with states and rules: the chain family of
:mod:`._plant_chain` designed at its defaults (no design defaults: the tool finds its parameters), each
member in a fresh process (:mod:`._growth_member`) so that its peak memory is its own."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from .._text import shorten

__all__ = ["bench_growth"]  # public: docs/api.md

#: (n, q): n states, q sin couplings (2^q rules); what ``fte bench`` runs by default
MEMBERS = ((2, 1), (4, 2), (8, 2), (4, 4), (6, 4))

#: a recorded baseline: the same family's times as measured with the design of 0.1 (one design at a sigma
#: found by hand; the defaults were refused, n = 16 and n = 24 failed numerically with Clarabel)
BASELINE_S = {(4, 2): 0.33, (4, 4): 1.6, (6, 6): 24.0, (8, 2): 1.1, (12, 2): 4.5}


def bench_growth(members=MEMBERS, log=lambda s: None) -> list[dict]:
    """One row per member: rules, wall time at the defaults (with the parameter search), the time of one
    design at the parameters found, peak resident memory of the process, and the recorded baseline."""
    root = str(Path(__file__).resolve().parents[2])  # the folder that holds fte_casadi/
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    rows = []
    for n, q in members:
        log(f"bench: design growth, chain n = {n}, {2**q} rules")
        with tempfile.TemporaryDirectory() as tmp:  # the member writes its row there
            out = Path(tmp) / "row.json"
            p = subprocess.run([sys.executable, "-m", "fte_casadi.bench._growth_member", str(n), str(q), str(out)],
                               capture_output=True, text=True, env=env, cwd=root)  # fmt: skip
            text = out.read_text() if out.exists() else ""
        try:
            row = json.loads(text)
        except ValueError:
            row = {
                "n": n,
                "q": q,
                "error": shorten((p.stderr.strip().splitlines() or ["no output"])[-1], 300),
            }
        row["baseline_s"] = BASELINE_S.get((n, q))
        rows.append(row)
    return rows


def growth_lines(rows: list[dict]) -> list[str]:
    """The table ``fte bench`` prints."""
    out = ["design growth (chain family at its defaults, a fresh process each; beside it, the recorded baseline,",
           "for its own chain of the same shape, one design at a sigma found by hand, the defaults refused):",
           "  states rules  at defaults  one design  peak RSS  certified  baseline (0.1)"]  # fmt: skip
    for r in rows:
        if "error" in r:
            out.append(f"  {r['n']:6d} {2 ** r['q']:5d}  failed: {shorten(r['error'], 120)}")
            continue
        issue = f"{r['baseline_s']:.2f} s" if r.get("baseline_s") else "-"
        out.append(f"  {r['n']:6d} {r['rules']:5d}  {r['wall_s']:9.2f} s  {r['one_design_s']:8.2f} s  "
                   f"{r['peak_rss_mb']:6.0f} MB  {str(r['certified']):9s}  {issue}")  # fmt: skip
    return out
