"""Accommodation after detection: a design that compensates a fault in the control only while it is detected.

The paper compensates every fault estimate at all times (``u = ... + Kf fhat``). During one fault, the
other faults' estimates show cross-talk (docs/interface.md, ``crosstalk_peak``), and ``Kf`` feeds it into
the plant: on a sensor fault, whose own column of ``Kf`` is zero, tolerant control can then leave the true
outputs worse than none. :func:`accommodated` returns the design with the gate of
:func:`fte_casadi.step.accommodation_gate`, its thresholds the detection thresholds of :mod:`._detect`,
calibrated on fault-free paths of the scenario:

- rule ``"explain"`` (:func:`protected`, what ``fte design`` writes): fault j is compensated while
  ``|fhat_j| >= threshold_j + sum_q kappa[j, q] |fhat_q| + overshoot_j m_j``, ``kappa`` the observer's cross-talk
  (:func:`fte_casadi.design._isolation.crosstalk`), ``overshoot_j`` how far its own estimate swings past a step of
  its fault and ``m_j`` the estimate's recent extreme of the other sign, decaying
  (:func:`fte_casadi.design._isolation.overshoot`): detected, and more than the other faults and its own fault's
  end can explain (the estimate of a fault that has just ended swings to the other sign: not compensated); each
  term ``kappa[j, q] |fhat_q|`` the smaller of it and ``crosstalk_held[j, q] M_q``, ``M_q`` fault q's largest
  estimate held in the memories (:func:`fte_casadi.design._isolation.crosstalk_held`);
- rule ``"isolate"`` (``fte simulate --accommodate``): fault j switches on when ``|fhat_j|`` reaches its
  threshold and its normalised residual ``r_j = |fhat_j| / threshold_j`` is the largest, and stays on
  (hysteresis) until ``r_j`` falls below the release ratio (default :data:`RELEASE`) or another fault switches
  on with a larger ratio; ``release=1`` is the memoryless gate.

The latches and the memories are state: they follow the observer state ``z`` in the step (``Design.nz``), so that the Python
step, the generated C and the FMU carry the same ones. The gate turns the closed loop into a switched system:
Theorems 1/5 certify the observer and each local controller, not the switching; only the Monte Carlo
measures it.
"""

from __future__ import annotations

import dataclasses

from ..design import Design, fed_faults
from ..errors import ParameterError, SimulationError
from ._engine import calibrate_detection

__all__ = ["accommodated", "protected"]

#: the seed offset of the paths :func:`protected` measures the gate on: paths apart from those a run with the
#: design's own seed draws, so that the choice is not judged on the paths that made it
SELECTION_SEED = 100
#: the default release ratio: a compensated fault is released when ``|fhat_j| / threshold_j`` falls below it
RELEASE = 0.5


def accommodated(design: Design, plant, scenario, *, paths: int, seed: int, false_alarm_rate: float | None = None,
                 dt: float | None = None, threads: int | None = None, release: float = RELEASE,
                 rule: str = "isolate", calibration_paths: int | None = None) -> Design:  # fmt: skip
    """``design`` with accommodation after detection, its thresholds calibrated at ``false_alarm_rate``
    (alarms per unit of the plant's time; default one per hour) on the fault-free paths that follow the run's
    ``paths`` (as many as the rate asks, or ``calibration_paths``; :func:`._engine.calibrate_detection`): the
    steady thresholds (the gate has no clock, so the start-up blocks' own thresholds are not used);
    ``release`` in (0, 1]: the ratio ``|fhat_j| / threshold_j`` below which a compensated fault is released
    (1: no hysteresis, the memoryless gate); ``rule`` ``"isolate"`` or ``"explain"`` (module docstring)."""
    if rule not in ("isolate", "explain"):
        raise ParameterError(f"the accommodation rule must be 'isolate' or 'explain'; got {rule!r}")
    if not (isinstance(release, (int, float)) and not isinstance(release, bool) and 0 < release <= 1):
        raise ParameterError(
            f"the release ratio must be a number in (0, 1] (1: no hysteresis); got {release!r}"
        )
    if plant.lf < 1:
        raise ParameterError(f"{plant.name}: the plant has no faults to accommodate")
    cal = calibrate_detection(design, plant, scenario, paths=paths, seed=seed, false_alarm_rate=false_alarm_rate,
                              dt=dt, threads=threads, calibration_paths=calibration_paths)  # fmt: skip
    thr, entries = cal.thresholds, cal.entries
    bad = [e["fault"] for e, v in zip(entries, thr) if not (v > 0 and v < float("inf"))]
    if bad:
        raise ParameterError(
            f"no detection threshold could be set for {', '.join(bad)} (fault-free estimates identically zero, or too "
            "few calibration paths): accommodation needs a positive finite threshold per fault"
        )
    acc = {
        "rule": rule,
        "thresholds": [float(v) for v in thr],
        "release": float(release),
        "false_alarm_rate": entries[0]["false_alarm_rate_asked"],
        "calibration": {
            "paths": entries[0]["calibration_paths"],
            "seed": int(seed),
            "scenario": scenario.name,
        },
    }
    listed = ", ".join(f"{e['fault']} {v:.4g}" for e, v in zip(entries, thr))
    held = ("memoryless" if release >= 1 else
            f"held until |fhat| / threshold < {float(release):g} or another fault switches on")  # fmt: skip
    if rule == "explain":
        acc["crosstalk"] = _crosstalk(design).tolist()
        ov, tau = _overshoot(design)
        acc["overshoot"], acc["memory_time"] = [float(v) for v in ov], float(tau)
        acc["crosstalk_held"] = _crosstalk_held(design, tau).tolist()
        held = "memoryless" if release >= 1 else f"held until that ratio < {float(release):g}"
        what = (
            "while detected and more than the other faults' estimates and its own overshoot explain (|fhat_j| >= "
            "threshold_j + sum_q crosstalk[j][q] |fhat_q| + overshoot_j m_j, m_j its estimate's recent extreme of the "
            "other sign, decaying in "
            + f"{acc['memory_time']:.3g}; crosstalk "
            + _ratios(design, acc["crosstalk"])
            + "; overshoot "
            + ", ".join(f"{v:.3g}" for v in acc["overshoot"])
            + "; each crosstalk term at most crosstalk_held[j][q] M_q, M_q fault q's largest |fhat_q| held: "
            + _ratios(design, acc["crosstalk_held"])
            + ")"
        )
    else:
        what = "only while detected and isolated"
    note = (f"accommodation after detection: a fault is compensated {what} (thresholds {listed}, calibrated on "
            f"{entries[0]['calibration_paths']} fault-free paths; {held})")  # fmt: skip
    return dataclasses.replace(design, accommodation=acc, status=[*design.status, note])


def _crosstalk(design: Design):
    from ..design import crosstalk

    return crosstalk(design.R, design.T, int(design.dims.n), int(design.dims.lf))


def _crosstalk_held(design: Design, tau: float):
    from ..design import crosstalk_held

    return crosstalk_held(design.R, design.T, int(design.dims.n), int(design.dims.lf), tau)


def _overshoot(design: Design):
    from ..design import overshoot

    return overshoot(design.R, design.T, int(design.dims.n), int(design.dims.lf))


def _ratios(design: Design, ct) -> str:
    names = list(design.names.get("faults") or [f"f{j + 1}" for j in range(len(ct))])
    return ", ".join(f"{names[j]} from {names[q]} {ct[j][q]:.3g}" for j in range(len(ct)) for q in range(len(ct))
                     if j != q)  # fmt: skip


def needs_gate(design: Design) -> bool:
    """True when some fault that tolerant control feeds into the plant (a nonzero column of ``Kf``) shows
    cross-talk from another fault (:func:`fte_casadi.design._isolation.crosstalk`): then always compensating it
    feeds the other faults into the plant, and :func:`protected` gates it."""
    lf = int(design.dims.lf)
    if lf < 2:
        return False
    ct = _crosstalk(design)
    return any(ct[j, q] > 0 for j in fed_faults(design) for q in range(lf) if q != j)


def protected(design: Design, plant, scenario, *, paths: int = 8, seed: int = 0, false_alarm_rate=None,
              dt=None, threads=None) -> Design:  # fmt: skip
    """``design`` as ``fte design`` writes it: where its faults' estimates cross-talk (:func:`needs_gate`) and the
    plant has a scenario with faults, with the gate of rule ``"explain"``, memoryless, calibrated on the
    scenario's fault-free paths (:func:`accommodated`), unless compensating every estimate always measures
    better on the scenario (:func:`_measured`); otherwise unchanged (every estimate compensated always, the
    paper: with one fault nothing can leak into its compensation, and a gate would only delay it)."""
    if scenario is None or not scenario.faults or design.accommodation is not None or not needs_gate(design):
        return design
    try:
        gated = accommodated(design, plant, scenario, paths=paths, seed=seed, false_alarm_rate=false_alarm_rate,
                             dt=dt, threads=threads, release=1.0, rule="explain")  # fmt: skip
    except (SimulationError, ParameterError) as exc:  # the design stands; its gate could not be calibrated
        why = " ".join(str(exc).split())
        note = (f"warning: every fault estimate is compensated always (no gate): its thresholds could not be calibrated "
                f"on the scenario's fault-free paths ({why})")  # fmt: skip
        return dataclasses.replace(design, status=[*design.status, note])
    return _measured(design, gated, plant, scenario, paths=paths, seed=seed, dt=dt, threads=threads)


def _measured(
    design: Design, gated: Design, plant, scenario, *, paths: int, seed: int, dt, threads
) -> Design:
    """The gate, or none, as they measure on ``paths`` paths of the scenario drawn with ``seed +``
    :data:`SELECTION_SEED` (not those ``fte simulate`` draws by default, nor the calibration's):
    every estimate compensated always is kept where no window's FTC true ratio and none of its outputs' is above
    1 on these paths (the figure itself, not its interval: the choice errs towards the gate) and its windows'
    ratios, worst first, are smaller than the gate's; the gate otherwise. Where a run fails, the other is kept.
    With the gate kept, a fault fed into u whose every own window measures worse than none with it is then never
    compensated (:func:`_never`)."""
    seed = seed + SELECTION_SEED
    got = {tag: _run(d, plant, scenario, paths=paths, seed=seed, dt=dt, threads=threads)
           for tag, d in (("gate", gated), ("always", design))}  # fmt: skip
    where = f"measured on {paths} paths (seed {seed}) of scenario {scenario.name!r}"
    always, gate = got["always"], got["gate"]
    if isinstance(always, str):
        note = f"the gate is kept: without it the run fails ({where}: {always})"
        return dataclasses.replace(gated, status=[*gated.status, note])
    if not always[0] and (isinstance(gate, str) or _worst_first(always[1]) < _worst_first(gate[1])):
        against = (
            f"the run with the gate fails ({gate})"
            if isinstance(gate, str)
            else f"{_fmt(gate[1])} with the gate"
        )
        note = (f"no gate: compensating every fault estimate always measures better ({where}): FTC true ratios per "
                f"window {_fmt(always[1])}, no window or output worse than none, against {against}")  # fmt: skip
        return dataclasses.replace(design, status=[*design.status, note])
    why = (f"without it tolerant control is worse than none ({'; '.join(always[0])})" if always[0] else
           f"without it the windows' FTC true ratios are {_fmt(always[1])}, with it {_fmt(gate[1])}")  # fmt: skip
    kept = dataclasses.replace(gated, status=[*gated.status, f"the gate is kept ({where}): {why}"])
    if isinstance(gate, str):
        return kept
    return _never(kept, gate, plant, scenario, paths=paths, seed=seed, dt=dt, threads=threads, where=where)


def _run(d: Design, plant, scenario, *, paths: int, seed: int, dt, threads):
    """``(worse, ratios, windows)`` of ``d`` on the scenario (no detection): the windows and outputs whose FTC true
    ratio is above 1, described; each window's ratio; the windows. The run's error, in words, where it fails."""
    from ..verdicts import WORSE_THAN_NONE
    from ..verdicts import window_label as _where
    from ._engine import simulate

    try:
        res = simulate(d, plant, scenario, paths=paths, seed=seed, dt=dt, threads=threads, progress=False,
                       detect=False)  # fmt: skip
    except (SimulationError, ParameterError) as exc:
        return " ".join(str(exc).split())
    wins = res.metrics.get("windows") or []
    names = list(d.names.get("outputs") or [])
    worse = [f"{_where(w)}: {r:.4g}" for w in wins for r in [w.get("ftc_true_ratio")]
             if r is not None and r > WORSE_THAN_NONE]  # fmt: skip
    worse += [f"{_where(w)} on {names[k] if k < len(names) else f'output {k}'}: {r:.4g}" for w in wins
              for k, r in enumerate(w.get("ftc_true_ratio_per_output") or [])
              if r is not None and r > WORSE_THAN_NONE]  # fmt: skip
    return worse, [w.get("ftc_true_ratio") for w in wins], wins


def _fmt(ratios) -> str:
    return ", ".join("n/a" if r is None else f"{r:.3g}" for r in ratios)


def _worst_first(ratios) -> list:
    return sorted((r for r in ratios if r is not None), reverse=True)


def _never(gated: Design, run, plant, scenario, *, paths: int, seed: int, dt, threads, where: str) -> Design:
    """``gated`` with ``accommodation["never"]``: the faults fed into u whose every own window measures worse than
    none with the gate (``run``, :func:`_run`); their compensation cannot help the true outputs on this scenario,
    so it is not fed to the plant (#38: per-fault decisions). Measured again on the same paths and kept only where
    the windows' ratios, worst first, are smaller; ``gated`` unchanged where no fault qualifies."""
    from ..verdicts import WORSE_THAN_NONE
    from ..verdicts import window_label as _where

    names = list(gated.names.get("faults") or [f"f{j + 1}" for j in range(int(gated.dims.lf))])
    wins = run[2]
    off = []
    for j in fed_faults(gated):
        own = [w.get("ftc_true_ratio") for w in wins if w.get("fault") == names[j]]
        if own and all(r is not None and r > WORSE_THAN_NONE for r in own):
            off.append(j)
    if not off:
        return gated
    trial = dataclasses.replace(gated, accommodation={**gated.accommodation, "never": off})
    again = _run(trial, plant, scenario, paths=paths, seed=seed, dt=dt, threads=threads)
    listed = ", ".join(names[j] for j in off)
    theirs = "; ".join(f"{_where(w)}: {w['ftc_true_ratio']:.4g}" for w in wins if w.get("fault") in
                       {names[j] for j in off})  # fmt: skip
    if isinstance(again, str) or not _worst_first(again[1]) < _worst_first(run[1]):
        after = again if isinstance(again, str) else f"the windows' FTC true ratios {_fmt(again[1])}"
        note = (f"warning: compensating {listed} measures worse than none in every one of its windows ({theirs}; "
                f"{where}), and not compensating it measures no better ({after}): it is compensated as the gate "
                "says")  # fmt: skip
        return dataclasses.replace(gated, status=[*gated.status, note])
    note = (f"{listed} never compensated: with the gate its compensation measures worse than none in every one of "
            f"its windows ({theirs}; {where}); without it the windows' FTC true ratios are {_fmt(again[1])}, "
            f"against {_fmt(run[1])}")  # fmt: skip
    return dataclasses.replace(trial, status=[*trial.status, note])
