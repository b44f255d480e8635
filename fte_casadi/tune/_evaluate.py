"""One candidate of ``fte tune``: designed, certified and simulated, as a pure function of its task.

A task is a plain dictionary (the plant as CasADi's serialisation of its equations, the scenario
as its document, the knobs, the seed and path count), so that the same function runs in this
process or on a dask.distributed worker and returns the same numbers: every candidate is
simulated with the same seed, hence the same Brownian paths, unknown inputs and initial states
(common random numbers).
"""

from __future__ import annotations

import functools
import hashlib
import json
import pickle

import numpy as np

from ..errors import FteError

__all__ = ["evaluate"]  # public: docs/api.md

#: the input peak (and the output-error scale of the boundary layer) is read from the first paths, recorded
PEAK_PATHS = 5
#: the knobs of the search, in the order of the tables
KNOBS = ("gamma", "gamma1_ratio", "sigma", "alpha_scale", "kappa", "epsilon", "use_boundary_layer",
         "boundary_layer_rel", "use_bound_weight", "bound_weight")  # fmt: skip


#: design defaults a plant may record from an earlier tune; the candidates set them from their own knobs
TUNED_DEFAULTS = ("alpha", "kappa", "boundary_layer", "bound_weight")


@functools.lru_cache(maxsize=4)
def _plant_ts(blob_hash: str, blob: bytes, vertices: str | None = None):
    """The plant and its T-S model (its premises covered as the base design's, ``vertices``), once per process
    and plant; the knobs of an earlier tune are
    removed from the plant's design defaults (a candidate's knobs set them: ``alpha`` as a fraction of
    the rate the design takes by default at the candidate's other knobs, not the base's fixed rate)."""
    import dataclasses

    import casadi as ca

    from ..ts import derive

    with ca.global_unpickle_context():
        plant = pickle.loads(blob)
    defaults = dict(getattr(plant, "design_defaults", {}) or {})
    if any(k in defaults for k in TUNED_DEFAULTS):
        kept = {k: v for k, v in defaults.items() if k not in TUNED_DEFAULTS}
        plant = dataclasses.replace(plant, design_defaults=kept)
    return plant, derive(plant, vertices=vertices)


def default_alpha(task: dict) -> float | None:
    """The observer decay rate the design takes by default (no alpha given) at ``task["knobs"]``:
    what the knob ``alpha_scale`` multiplies, read as the candidates read it
    (:func:`~fte_casadi.design.default_observer_rate`); None when that design fails."""
    from ..design import default_observer_rate

    blob = task["plant"]
    _, ts = _plant_ts(hashlib.sha256(blob).hexdigest(), blob, task.get("vertices"))
    return default_observer_rate(ts, variant=task["variant"], solver=task["solver"], sample_time=task["sample_time"],
                                 initial_state=task["initial_state"], plant_spec=task["plant_spec"], diagnose=False,
                                 **design_kwargs(task["knobs"]))  # fmt: skip


def design_kwargs(knobs: dict) -> dict:
    """The arguments of :func:`fte_casadi.design.design` a candidate's knobs give (alpha aside)."""
    from ..design import KAPPA

    g = float(knobs["gamma"])
    kw = {"gamma": g, "gamma1": float(knobs["gamma1_ratio"]) * g, "sigma": float(knobs["sigma"]),
          "epsilon": float(knobs["epsilon"])}  # fmt: skip
    if "delta" in knobs:
        kw["delta"] = float(knobs["delta"])
    if abs(float(knobs["kappa"]) / KAPPA - 1.0) > 1e-12:
        kw["kappa"] = float(knobs["kappa"])
    if knobs.get("use_bound_weight"):
        kw["bound_weight"] = float(knobs["bound_weight"])
    return kw


def bound_gain(bounds: dict | None) -> float | None:
    """The certified L2 gain from the stacked channels ``w = [d; f''; u_s; f; 1]`` to ``f - fhat`` of a
    design's ``bounds.fault_error`` (:mod:`fte_casadi.design.core._bounds`): ``max_k gain_k``, since
    ``E int |f - fhat|^2 <= sum_k gain_k^2 E int |w_k|^2 + v0 <= max_k gain_k^2 E int |w|^2 + v0``.
    None when the bound was not computed or does not hold."""
    fe = (bounds or {}).get("fault_error") or {}
    gains = fe.get("gains") or {}
    if not fe.get("holds") or not gains:
        return None
    return float(max(gains.values()))


def _output_error_scale(res, design) -> float:
    """RMS over paths, t >= 1 and outputs of ``y - Cbar xbarhat`` in the FTC run (the scale of the
    sliding variable before N)."""
    ftc = res.ftc
    keep = res.t >= 1.0
    if ftc.y.shape[0] == 0 or not keep.any():
        return 0.0
    p = design.C.shape[0]
    lf = design.Df.shape[1]
    Cbar = np.hstack([design.C, np.zeros((p, lf)), design.Df])
    e = ftc.y[:, keep, :] - np.einsum("ij,abj->abi", Cbar, ftc.xbarhat[:, keep, :])
    return float(np.sqrt(np.mean(e**2)))


def evaluate(task: dict) -> dict:
    """Design, certify and simulate one candidate.

    ``task`` keys: ``plant`` (bytes), ``scenario`` (dict), ``variant``, ``solver``, ``knobs``,
    ``sample_time``, ``initial_state``, ``plant_spec``, ``paths``, ``seed``, ``e_scale`` (the
    output-error scale the relative boundary layer multiplies), and ``design`` (a design document
    as JSON: simulate that one instead of designing; the baseline of a DESIGN.json).

    Returns ``{"state": "ok", "params", "metrics", "design", "e_scale"}`` or
    ``{"state": "fail", "reason"}``. The metrics document gains ``input_peak``: per input, the
    largest ``|u_i|`` of the FTC run over the first :data:`PEAK_PATHS` paths (their recorded
    samples, at most ~2e4 per path) and ``fault_error_bound`` (:func:`bound_gain` of the design's certified
    bound, None when not computed). Never raises for a candidate that fails (a failed design, a
    design that is not certified, a diverging simulation are failed trials with their reason).
    """
    from ..design import failures
    from ..sim import Scenario, protected, simulate

    blob = task["plant"]
    plant, ts = _plant_ts(hashlib.sha256(blob).hexdigest(), blob, task.get("vertices"))
    scenario = Scenario.from_dict(task["scenario"])
    try:
        d = _candidate(task, ts, dict(task["knobs"]))
        if not d.certified:
            return {
                "state": "fail",
                "reason": "not certified: " + "; ".join(failures(d.checks)),
            }
        if (
            task.get("design") is None
        ):  # as fte design writes it: the gate where the faults' estimates cross-talk
            d = protected(d, plant, scenario, paths=int(task["paths"]), seed=int(task["seed"]),
                          threads=task.get("threads"))  # fmt: skip
        res = simulate(d, plant, scenario, paths=int(task["paths"]), seed=int(task["seed"]), progress=False,
                       record_paths=PEAK_PATHS, threads=task.get("threads"), detect=False)  # fmt: skip
    except FteError as exc:
        return {"state": "fail", "reason": f"{type(exc).__name__}: {' '.join(str(exc).split())}"}
    m = dict(res.metrics)
    u = res.ftc.u
    m["input_peak"] = [float(v) for v in np.max(np.abs(u), axis=(0, 1))] if u.size else [0.0] * plant.m
    m["fault_error_bound"] = bound_gain(d.bounds)
    return {"state": "ok", "params": _candidate_params(d), "metrics": m, "design": d.to_json(),
            "e_scale": _output_error_scale(res, d)}  # fmt: skip


def _candidate(task: dict, ts, knobs: dict):
    """The candidate's design: the design document of the task (the one tuned from), or a design at its knobs,
    with the decay rate scaled and the relative boundary layer applied when the knobs ask for them."""
    import dataclasses

    from ..design import Design, design_at_rate_fraction
    from ..design import design as run_design

    if task.get("design") is not None:
        return Design.from_dict(json.loads(task["design"]), source="the design tuned from")
    common = dict(variant=task["variant"], solver=task["solver"], sample_time=task["sample_time"],
                  initial_state=task["initial_state"], plant_spec=task["plant_spec"], diagnose=False,
                  **design_kwargs(knobs))  # fmt: skip
    scale = float(knobs["alpha_scale"])
    if abs(scale - 1.0) > 1e-12:
        d = design_at_rate_fraction(ts, scale, **common)
    else:
        d = run_design(ts, **common)
    if knobs.get("use_boundary_layer") and task.get("e_scale"):
        phi = float(knobs["boundary_layer_rel"]) * float(np.linalg.norm(d.N, 2)) * float(task["e_scale"])
        if phi > 0 and np.isfinite(phi):
            d = dataclasses.replace(d, params=d.params.replace(boundary_layer=phi))
    return d


def _candidate_params(d) -> dict:
    """The design's params as a trial records them: the LMI parameters, the decay rate, kappa, the boundary layer
    and the bound's weight (None where not set)."""
    from ..design import KAPPA

    params = d.params.to_dict()
    params["alpha"] = None if d.observer.alpha is None else float(d.observer.alpha)
    params.setdefault("kappa", KAPPA)
    params.setdefault("boundary_layer", None)
    params.setdefault("bound_weight", None)
    return params
