"""The figure of the smallest fault a design can see: detection probability against the fault's size."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._atomic import atomic_write

__all__ = ["detectability_plot", "detectability_figure"]


def _arrays(curve: dict):
    size = np.array([np.nan if v is None else v for v in curve["size"]], dtype=float)
    prob = np.array([np.nan if v is None else v for v in curve["probability"]], dtype=float)
    iv = np.array([[np.nan, np.nan] if v is None else v for v in curve["interval"]], dtype=float)
    return size, prob, iv


def detectability_plot(sets: list[dict], plant: str, units: dict | None = None) -> Figure:
    """One panel per fault: the detection probability within the allowed delay against the fault's size (log
    scale), one curve per set of :func:`fte_casadi.sim.detectability` (e.g. without and with measurement noise),
    the 95 % binomial interval of each point as a bar, the target and the minimum detectable fault marked."""
    faults = [c["fault"] for c in sets[0]["curves"]]
    fig = Figure(figsize=(4.2 * len(faults), 3.6), layout="constrained")
    FigureCanvasAgg(fig)
    styles = ["o-", "s--", "^:", "d-."]
    for k, fault in enumerate(faults):
        ax = fig.add_subplot(1, len(faults), k + 1)
        for s, st in zip(sets, styles):
            c = next(c for c in s["curves"] if c["fault"] == fault)
            size, prob, iv = _arrays(c)
            keep = np.isfinite(size) & (size > 0) & np.isfinite(prob)
            label = s.get("label") or "run"
            (line,) = ax.plot(size[keep], prob[keep], st, ms=4, label=label)
            ax.errorbar(size[keep], prob[keep], yerr=[prob[keep] - iv[keep, 0], iv[keep, 1] - prob[keep]], fmt="none",
                        ecolor=line.get_color(), alpha=0.5, capsize=2)  # fmt: skip
            if c.get("min_detectable_fault"):
                ax.axvline(c["min_detectable_fault"], color=line.get_color(), lw=0.8, ls=":")
        ax.axhline(sets[0].get("target", 0.95), color="tab:red", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_ylim(-0.03, 1.03)
        unit = (units or {}).get(fault)
        ax.set_xlabel(f"size of {fault}" + (f" ({unit})" if unit else "") + ": largest |f| in its windows")
        delay = next(c["delay"] for c in sets[0]["curves"] if c["fault"] == fault)
        ax.set_ylabel("detection probability" + (f" within {delay:.3g}" if delay is not None else ""))
        ax.grid(True, alpha=0.3)
        ax.legend(fontsize=7)
    fig.suptitle(f"{plant}: the smallest fault each design sees (dotted: the size detected on 95 % of the paths)",
                 fontsize=10)  # fmt: skip
    return fig


def detectability_figure(sets: list[dict], plant: str, out_dir: str | os.PathLike, units: dict | None = None,
                         name: str = "detectability.png") -> Path:  # fmt: skip
    """:func:`detectability_plot` written as PNG into ``out_dir``."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / name
    fig = detectability_plot(sets, plant, units)
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return path
