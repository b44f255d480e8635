"""The Pareto front of ``fte tune``: every completed trial, the front, the base and the chosen design."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._atomic import atomic_write

__all__ = ["pareto_plot", "pareto_figure"]


def _group(names, values, prefix):
    cols = [k for k, n in enumerate(names) if n.startswith(prefix)]
    return None if not cols else np.max(np.asarray(values, float)[:, cols], axis=1)


def pareto_plot(result) -> Figure:
    """Two panels over the completed trials of a :class:`~fte_casadi.tune.TuneResult`: the largest
    fault error against the worst window's FTC ratio, and against the largest false-alarm ratio.
    Grey: all completed trials; orange: the Pareto front (over every objective); black star: the
    base design (trial 0); red star: the chosen design."""
    names = result.objectives
    done = [r for r in result.records if r.state == "ok"]
    vals = [r.values for r in done]
    err = _group(names, vals, "fault_error")
    others = [("ftc[", "worst window's FTC deviation ratio"), ("false_alarm", "largest false-alarm ratio")]
    panels = [(_group(names, vals, p), lab) for p, lab in others if _group(names, vals, p) is not None]
    fig = Figure(figsize=(5.2 * max(1, len(panels)), 4.4), layout="constrained")
    FigureCanvasAgg(fig)
    if err is None or not panels:
        ax = fig.add_subplot()
        ax.text(0.5, 0.5, "no fault error to plot", ha="center", va="center")
        return fig
    num = [r.number for r in done]
    on_front = np.array([n in result.front for n in num])
    base, chosen = num.index(0), num.index(result.chosen)
    for k, (other, label) in enumerate(panels):
        ax = fig.add_subplot(1, len(panels), k + 1)
        ax.scatter(err, other, s=14, color="tab:gray", alpha=0.5, label="certified trials")
        ax.scatter(
            err[on_front], other[on_front], s=24, color="tab:orange", label="Pareto front (all objectives)"
        )
        ax.plot(err[base], other[base], "*", ms=15, color="black", label="base design (trial 0)")
        ax.plot(
            err[chosen], other[chosen], "*", ms=13, color="tab:red", label=f"chosen (trial {result.chosen})"
        )
        ax.axhline(1.0, color="tab:red", ls=":", lw=1)
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("largest fault relative RMS error in its windows")
        ax.set_ylabel(label)
        ax.grid(True, which="both", alpha=0.3)
        if k == 0:
            ax.legend(fontsize=7, loc="best")
    failed = sum(1 for r in result.records if r.state != "ok")
    fig.suptitle(f"{result.plant}: {len(result.records)} trials ({failed} failed: not designed or not certified), "
                 f"rule {result.rule}", fontsize=10)  # fmt: skip
    return fig


def pareto_figure(result, out_dir: str | os.PathLike) -> Path:
    """Write :func:`pareto_plot` as ``out_dir/pareto.png`` and return its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "pareto.png"
    fig = pareto_plot(result)
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return path
