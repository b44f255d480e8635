"""The feasible frontier of a design (``fte design PLANT --explore``): smallest gamma over sigma."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._atomic import atomic_write

__all__ = ["frontier_figure", "frontier_plot"]


def frontier_plot(points, info: dict, plant: str) -> Figure:
    """The frontier as a Figure: LMI (45) is feasible above the grey curve; green points are the
    smallest gammas tried whose whole design is certified; the star is the plant's default (gamma, sigma)."""
    fig = Figure(figsize=(6.4, 4.2), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    sig = np.array([p.sigma for p in points if p.gamma_min is not None])
    gmin = np.array([p.gamma_min for p in points if p.gamma_min is not None])
    if len(sig):
        ax.plot(sig, gmin, "-", color="tab:gray", label="smallest feasible gamma of (45)")
        top = max(float(gmin.max()), info["gamma"]) * 3
        ax.fill_between(sig, gmin, top, color="tab:green", alpha=0.08, label="(45) feasible")
    ok = [p for p in points if p.certified]
    bad = [p for p in points if p.gamma_tried is not None and not p.certified]
    if ok:
        ax.plot([p.sigma for p in ok], [p.gamma_tried for p in ok], "o-", color="tab:green",
                label="smallest gamma tried with a certified design")  # fmt: skip
    if bad:
        ax.plot([p.sigma for p in bad], [p.gamma_min for p in bad], "x", color="tab:red",
                label="no certified design up to 10 x gamma_min")  # fmt: skip
    if info.get("sigma_sup"):
        ax.axvline(info["sigma_sup"], color="tab:red", ls=":", lw=1, label="no gamma beyond this sigma")
    ax.plot([info["sigma"]], [info["gamma"]], "*", ms=12, color="tab:orange", label="the plant's defaults")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("sigma")
    ax.set_ylabel("gamma")
    ax.set_title(f"{plant}: feasible frontier (gamma1 = {info['gamma1']:g})", fontsize=10)
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7, loc="best")
    return fig


def frontier_figure(points, info: dict, plant: str, out_dir: str | os.PathLike) -> Path:
    """Write :func:`frontier_plot` as ``out_dir/frontier-PLANT.png`` and return its path."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / f"frontier-{''.join(c if c.isalnum() or c in '-_' else '_' for c in plant)}.png"
    fig = frontier_plot(points, info, plant)
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return path
