"""Robustness sweeps: the Monte Carlo over a grid of ``fault_scale``, ``noise_scale`` and ``d_scale``.

Each point of the grid runs the scenario with every fault's magnitude, the diffusion or the
unknown input multiplied by its factor, on the same compiled engine (the factors are runtime
inputs: no recompilation per point), in-process or on a cluster, with one progress bar over all
points. The result is a list of ``{"point": {NAME: value}, "metrics": <metrics document>}``.
"""

from __future__ import annotations

import csv
import io
import itertools
import json
import math
import sys
from typing import TYPE_CHECKING

from tqdm import tqdm

from ..errors import ParameterError
from ._engine import SCALES, Prepared, _check_settings, _scales, calibrate_detection, resolve_dt, simulate

if TYPE_CHECKING:  # an optional dependency (the [dask] extra)
    import distributed

__all__ = ["sweep"]  # public: docs/api.md


def parse_vary(items) -> dict[str, list[float]]:
    """``["fault_scale=0.5,1,2", ...]`` -> ``{"fault_scale": [0.5, 1.0, 2.0]}`` (order kept), validated."""
    out: dict[str, list[float]] = {}
    for item in items:
        if "=" not in item:
            raise ParameterError(f"--vary {item!r}: write NAME=V1,V2,... with NAME one of {sorted(SCALES)}")
        name, vals = item.split("=", 1)
        name = name.strip()
        if name not in SCALES:
            raise ParameterError(f"--vary: unknown factor {name!r}; the factors are {sorted(SCALES)}")
        if name in out:
            raise ParameterError(
                f"--vary: factor {name!r} given twice; give its values once, separated by commas"
            )
        try:
            values = [float(v) for v in vals.split(",") if v.strip()]
        except ValueError:
            raise ParameterError(f"--vary {item!r}: the values must be numbers separated by commas") from None
        if not values:
            raise ParameterError(f"--vary {item!r}: give at least one value")
        bad = [v for v in values if not (math.isfinite(v) and v >= 0)]
        if bad:
            raise ParameterError(f"--vary {name}: values must be non-negative finite numbers; got {bad}")
        out[name] = values
    if not out:
        raise ParameterError(f"give at least one --vary NAME=V1,V2,... with NAME one of {sorted(SCALES)}")
    return out


def sweep(design, plant, scenario, vary: dict[str, list[float]], *, paths: int, seed: int, dt=None,
          scheduler: str | distributed.Client | None = None, threads: int | None = None, progress: bool = True,
          exact: bool = True) -> list[dict]:  # fmt: skip
    """The metrics document of the scenario at every point of the grid ``vary`` (first factor slowest);
    ``exact=False``: the fast mode of :func:`._engine.simulate`."""
    _check_settings(design, plant, paths, seed, dt)
    grid = [dict(zip(vary, combo)) for combo in itertools.product(*vary.values())]
    for point in grid:  # every point checked before the first runs
        _scales(point, scenario)
    dt, nsteps, _ = resolve_dt(design, scenario, dt)
    base = Prepared(design, plant, scenario, dt, nsteps, _scales(None), exact=bool(exact))
    out = []
    client = None
    if isinstance(scheduler, str):  # one client for all points
        from ._cluster import client_for

        client = scheduler = client_for(scheduler)
    bar = tqdm(total=len(grid) * paths, disable=not progress, delay=1.0, file=sys.stderr, unit=" paths",
               desc=f"sweep {plant.name} ({len(grid)} points)")  # fmt: skip
    cals: dict = {}  # the thresholds depend on the fault-free behaviour only: one calibration per other factors
    try:
        for point in grid:
            sc = _scales(point, scenario)
            prep = base.rescaled(sc)
            key = tuple(sorted((k, v) for k, v in sc.items() if k != "fault_scale"))
            if key not in cals and plant.lf:
                cals[key] = calibrate_detection(design, plant, scenario, paths=paths, seed=seed, prepared=prep,
                                                threads=threads, scheduler=scheduler)  # fmt: skip
            res = simulate(design, plant, scenario, paths=paths, seed=seed, dt=dt, progress=False, record_paths=0,
                           threads=threads, scheduler=scheduler, scales=sc, prepared=prep, exact=bool(exact),
                           calibration=cals.get(key))  # fmt: skip
            out.append({"point": dict(point), "metrics": res.metrics})
            bar.update(paths)
    finally:
        bar.close()
        if client is not None:
            client.close()
    return out


def to_csv(points: list[dict]) -> str:
    """One row per point: the factors, then the scalar metrics and each window's two ratios."""
    if not points:
        return ""
    factors = list(points[0]["point"])
    m0 = points[0]["metrics"]
    lf = len(m0["fault_rel_rms_error"])
    cols = factors + [f"fault_rel_rms_error_{j}" for j in range(lf)] + ["ftc_true_ratio"]
    for w in m0["windows"]:
        tag = f"{w['fault']}_{w['start']:g}_{w['stop']:g}"
        cols += [f"window_{tag}_fault_rel_rms_error", f"window_{tag}_ftc_true_ratio"]
    buf = io.StringIO()
    wr = csv.writer(buf)
    wr.writerow(cols)
    for p in points:
        m = p["metrics"]
        row = [p["point"][f] for f in factors] + list(m["fault_rel_rms_error"]) + [m["ftc_true_ratio"]]
        for w in m["windows"]:
            row += [w["fault_rel_rms_error"], w["ftc_true_ratio"]]
        wr.writerow(["" if v is None else v for v in row])
    return buf.getvalue()


def to_json(points: list[dict]) -> str:
    return json.dumps(points, indent=1)
