"""The figure of a robustness sweep (``fte sweep``): fault estimation error and FTC true ratio
over the grid — curves for one varying factor, heat maps for two."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._atomic import atomic_write

__all__ = ["sweep_plot", "sweep_figure"]


def _val(v) -> float:
    return float("nan") if v is None else float(v)


def sweep_plot(points: list[dict], plant: str, fault_names=None) -> Figure:
    factors = [f for f in points[0]["point"] if len({p["point"][f] for p in points}) > 1] or list(
        points[0]["point"]
    )
    lf = len(points[0]["metrics"]["fault_rel_rms_error"])
    names = list(fault_names or [f"f{j}" for j in range(lf)])
    if len(factors) == 2:
        fx, fy = factors
        xs = sorted({p["point"][fx] for p in points})
        ys = sorted({p["point"][fy] for p in points})
        fig = Figure(figsize=(10, 4), layout="constrained")
        FigureCanvasAgg(fig)
        panels = [("mean fault relative RMS error", lambda m: np.nanmean([_val(v) for v in m["fault_rel_rms_error"]])),
                  ("FTC true ratio", lambda m: _val(m["ftc_true_ratio"]))]  # fmt: skip
        for k, (title, get) in enumerate(panels):
            Z = np.full((len(ys), len(xs)), np.nan)
            for p in points:
                Z[ys.index(p["point"][fy]), xs.index(p["point"][fx])] = get(p["metrics"])
            ax = fig.add_subplot(1, 2, k + 1)
            im = ax.imshow(Z, origin="lower", aspect="auto", cmap="viridis")
            ax.set_xticks(range(len(xs)), [f"{v:g}" for v in xs])
            ax.set_yticks(range(len(ys)), [f"{v:g}" for v in ys])
            ax.set_xlabel(fx)
            ax.set_ylabel(fy)
            ax.set_title(title, fontsize=10)
            for i in range(len(ys)):
                for j in range(len(xs)):
                    ax.text(j, i, f"{Z[i, j]:.3g}", ha="center", va="center", fontsize=7, color="w")
            fig.colorbar(im, ax=ax)
        fig.suptitle(f"{plant}: sweep over {fx} and {fy}", fontsize=11)
        return fig
    fig = Figure(figsize=(7, 4), layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    if len(factors) == 1:
        f = factors[0]
        x = [p["point"][f] for p in points]
        ax.set_xlabel(f)
    else:
        x = list(range(len(points)))
        ax.set_xlabel("point (" + ", ".join(factors) + ")")
    for j in range(lf):
        ax.plot(x, [_val(p["metrics"]["fault_rel_rms_error"][j]) for p in points], "o-",
                label=f"fault relative RMS error, {names[j]}")  # fmt: skip
    ax.plot(
        x,
        [_val(p["metrics"]["ftc_true_ratio"]) for p in points],
        "s--",
        color="k",
        label="FTC true ratio",
    )
    ax.axhline(1.0, color="tab:red", lw=0.8, ls=":")
    ax.set_title(f"{plant}: robustness sweep", fontsize=10)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=8)
    return fig


def sweep_figure(points: list[dict], plant: str, out_dir: str | os.PathLike, fault_names=None) -> Path:
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    path = out / "sweep.png"
    fig = sweep_plot(points, plant, fault_names)
    atomic_write(path, lambda fh: fig.savefig(fh, format="png", dpi=110))
    return path
