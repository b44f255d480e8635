"""Figures from SimulationResult objects: the paper's Figs 2-10 (manipulator) and 11-16 (three-tank).

Each function takes a result and returns a matplotlib Figure; nothing here computes a
simulation or calls ``show()``. Figures are built on the object-oriented API with the Agg
canvas, so they work without a display and never touch pyplot's global state.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure

from .._atomic import atomic_write
from ..sim._result import RUN_TITLES, SimulationResult

__all__ = [
    "state_figure",
    "fault_figure",
    "output_figure",
    "output_paths_figure",
    "output_means_figure",
    "figure_set",
    "write_figures",
]

_RUN_COLORS = {"free": "tab:green", "no_ftc": "tab:red", "ftc": "tab:blue"}
#: paper figure numbers for the built-in examples
_PAPER = {
    "manipulator": {"states": (2, 3, 4, 5), "faults": (6, 7), "outputs": (8, 9, 10)},
    "three-tank": {"states": (11, 12, 13), "faults": (14,), "output_paths": {1: 15}, "output_means": {1: 16}},
}


def _new(title: str, size=(7.0, 3.6)) -> tuple[Figure, object]:
    fig = Figure(figsize=size, layout="constrained")
    FigureCanvasAgg(fig)
    ax = fig.add_subplot()
    ax.set_title(title, fontsize=10)
    ax.grid(True, alpha=0.3)
    return fig, ax


def _unit(units, k) -> str:
    u = units[k] if units and k < len(units) else ""
    return f" [{u}]" if u else ""


def _tlabel(result: SimulationResult) -> str:
    return f"time [{result.names.get('time_unit', 's')}]"


def _paper(result: SimulationResult, key: str, k: int):
    fig = _PAPER.get(result.plant, {}).get(key)
    if fig is None:
        return None
    if isinstance(fig, dict):
        return fig.get(k)
    return fig[k] if k < len(fig) else None


def _prefix(num) -> str:
    return f"Fig. {num} (paper): " if num is not None else ""


def _band(ax, t, data, color, label, *, lw=1.2, ls="-"):
    """Mean over paths as a line, min-max over paths as a band. data: (paths, samples)."""
    ax.plot(t, data.mean(axis=0), color=color, lw=lw, ls=ls, label=label)
    if data.shape[0] > 1:
        ax.fill_between(t, data.min(axis=0), data.max(axis=0), color=color, alpha=0.2, lw=0)


def _shade_faults(ax, result: SimulationResult, fault: str | None = None):
    for fp in result.scenario.faults:
        if fault is None or fp.fault == fault:
            ax.axvspan(fp.start, min(fp.stop, result.T), color="0.85", alpha=0.5, lw=0, zorder=0)


def state_figure(result: SimulationResult, k: int, run: str = "ftc") -> Figure:
    """State ``k`` and its estimate: mean over paths with a min-max band (tolerant-control run)."""
    nm, units = result.names["states"][k], result.names.get("state_units", [])
    fig, ax = _new(
        f"{_prefix(_paper(result, 'states', k))}{nm} and its estimate ({RUN_TITLES[run]}, "
        f"{result.paths} paths)"
    )
    rd = result.run(run)
    _shade_faults(ax, result)
    _band(ax, result.t, rd.x[:, :, k], "tab:blue", f"{nm} (mean, min-max band)")
    _band(ax, result.t, rd.xhat[:, :, k], "tab:orange", f"estimate of {nm}", ls="--")
    ax.set_xlabel(_tlabel(result))
    ax.set_ylabel(f"{nm}{_unit(units, k)}")
    ax.legend(fontsize=8, loc="best")
    return fig


def _fault_unit(result: SimulationResult, j: int) -> str:
    kind = result.names.get("fault_kinds", [""] * (j + 1))[j]
    if kind == "sensor":
        Df = np.asarray(result.design.Df)
        rows = np.flatnonzero(Df[:, j])
        if len(rows):
            return _unit(result.names.get("output_units", []), int(rows[0]))
    return " (in input units)" if kind == "actuator" else ""


def fault_figure(result: SimulationResult, j: int, run: str = "ftc") -> Figure:
    """Fault ``j`` (true, mean and band over paths) and its estimate ``fhat``."""
    nm = result.names["faults"][j]
    kind = result.names.get("fault_kinds", [""] * (j + 1))[j]
    fig, ax = _new(
        f"{_prefix(_paper(result, 'faults', j))}{kind} fault {nm} and its estimate ({RUN_TITLES[run]})"
    )
    rd = result.run(run)
    _shade_faults(ax, result, nm)
    _band(ax, result.t, rd.f[:, :, j], "tab:red", f"{nm} (true)")
    _band(ax, result.t, rd.fhat[:, :, j], "tab:blue", f"estimate of {nm}", ls="--")
    ax.set_xlabel(_tlabel(result))
    ax.set_ylabel(f"{nm}{_fault_unit(result, j)}")
    ax.legend(fontsize=8, loc="best")
    return fig


def _output_three(result: SimulationResult, k: int):
    """Per run: the output the user sees (y fault-free, y without FTC, yc with FTC)."""
    return {"free": result.free.y[:, :, k], "no_ftc": result.no_ftc.y[:, :, k], "ftc": result.ftc.yc[:, :, k]}


def output_figure(result: SimulationResult, k: int) -> Figure:
    """Output ``k`` three ways (fault-free y, faulty y without FTC, reliable yc with FTC): mean and band."""
    nm, units = result.names["outputs"][k], result.names.get("output_units", [])
    fig, ax = _new(
        f"{_prefix(_paper(result, 'outputs', k))}output {nm}: fault-free, faulty without and with "
        "tolerant control"
    )
    _shade_faults(ax, result)
    for run in ("no_ftc", "ftc", "free"):  # fault-free last and dashed: it lies under a good yc
        data = _output_three(result, k)[run]
        _band(
            ax,
            result.t,
            data,
            _RUN_COLORS[run],
            RUN_TITLES[run] + (" (yc)" if run == "ftc" else ""),
            ls="--" if run == "free" else "-",
        )
    ax.set_xlabel(_tlabel(result))
    ax.set_ylabel(f"{nm}{_unit(units, k)}")
    ax.legend(fontsize=8, loc="best")
    return fig


def output_paths_figure(result: SimulationResult, k: int) -> Figure:
    """Output ``k`` three ways, one thin line per path."""
    nm, units = result.names["outputs"][k], result.names.get("output_units", [])
    fig, ax = _new(f"{_prefix(_paper(result, 'output_paths', k))}output {nm} per path ({result.paths} paths)")
    _shade_faults(ax, result)
    for run, data in _output_three(result, k).items():
        for q in range(data.shape[0]):
            ax.plot(
                result.t,
                data[q],
                color=_RUN_COLORS[run],
                lw=0.6,
                alpha=0.6,
                label=RUN_TITLES[run] if q == 0 else None,
            )
    ax.set_xlabel(_tlabel(result))
    ax.set_ylabel(f"{nm}{_unit(units, k)}")
    ax.legend(fontsize=8, loc="best")
    return fig


def output_means_figure(result: SimulationResult, k: int) -> Figure:
    """Output ``k`` three ways: means over paths only."""
    nm, units = result.names["outputs"][k], result.names.get("output_units", [])
    fig, ax = _new(f"{_prefix(_paper(result, 'output_means', k))}output {nm}: mean over {result.paths} paths")
    _shade_faults(ax, result)
    for run in ("no_ftc", "ftc", "free"):
        data = _output_three(result, k)[run]
        ax.plot(
            result.t,
            data.mean(axis=0),
            color=_RUN_COLORS[run],
            lw=1.2,
            ls="--" if run == "free" else "-",
            label=RUN_TITLES[run],
        )
    ax.set_xlabel(_tlabel(result))
    ax.set_ylabel(f"{nm}{_unit(units, k)}")
    ax.legend(fontsize=8, loc="best")
    return fig


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9]+", "_", text).strip("_").lower() or "x"


def figure_set(result: SimulationResult) -> list[tuple[str, object]]:
    """``(file stem, zero-argument builder)`` for every figure of ``result``, in the paper's order.

    The manipulator gets Figs 2-10 (states, faults, outputs three ways); the three-tank
    Figs 11-16 (states, fault, y2 per path, y2 means). Any other plant: states, faults,
    outputs three ways, then outputs per path, numbered from 1.
    """
    names = result.names
    out: list[tuple[str, object]] = []
    plan = _PAPER.get(result.plant)
    items = [("states", k, state_figure) for k in range(len(names["states"]))]
    items += [("faults", j, fault_figure) for j in range(len(names["faults"]))]
    if plan is None or "outputs" in plan:
        items += [("outputs", k, output_figure) for k in range(len(names["outputs"]))]
    if plan is None:
        items += [("output_paths", k, output_paths_figure) for k in range(len(names["outputs"]))]
    else:
        items += [("output_paths", k, output_paths_figure) for k in plan.get("output_paths", {})]
        items += [("output_means", k, output_means_figure) for k in plan.get("output_means", {})]
    label = {
        "states": names["states"],
        "faults": names["faults"],
        "outputs": names["outputs"],
        "output_paths": [f"{o}_paths" for o in names["outputs"]],
        "output_means": [f"{o}_means" for o in names["outputs"]],
    }
    for num, (key, k, fn) in enumerate(items, start=1):
        paper = _paper(result, key, k)
        number = paper if paper is not None else num
        out.append((f"fig{number:02d}_{_slug(label[key][k])}", (lambda fn=fn, k=k: fn(result, k))))
    return out


def write_figures(result: SimulationResult, directory: str | os.PathLike, *, dpi: int = 120) -> list[Path]:
    """Write every figure of ``result`` as PNG into ``directory`` (created); return the paths."""
    folder = Path(directory)
    folder.mkdir(parents=True, exist_ok=True)
    paths = []
    for stem, build in figure_set(result):
        fig = build()
        path = folder / f"{stem}.png"
        atomic_write(path, lambda fh, fig=fig: fig.savefig(fh, format="png", dpi=dpi))
        paths.append(path)
    return paths
