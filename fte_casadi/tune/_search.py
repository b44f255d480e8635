"""``tune``: a multi-objective search over a design's knobs (optuna), its Pareto front and the chosen design.

Trial 0 is the base design (today's default, or the DESIGN.json tuned from), evaluated first so
that every objective can be read against it. The other trials are asked from optuna's TPE sampler
(multivariate, multi-objective, seeded) in batches of :data:`BATCH`, evaluated in this process or
on a dask.distributed cluster, and told back in trial order: the same seed gives the same trials,
the same front and the same chosen design, wherever the candidates ran.

Objectives (all minimised; those the base design leaves undefined are dropped):

- ``fault_error[F]``: fault F's relative RMS error in its windows (metrics ``fault_rel_rms_error``);
- ``false_alarm[F]``: F's estimate outside its windows relative to F (``false_alarm_peak``);
- ``ftc[F@t0]``: the FTC true ratio in the window of F starting at t0
  (``windows[].ftc_true_ratio``; one objective per window, so that the worst window, and every
  window, can be read off the front);
- ``input_peak``: the largest ``max |u_i|`` over the inputs, each relative to the base design's;
- ``input_saturation``: the largest fraction of samples an input spends at a limit (plants with limits);
- ``bound[fault_error]``: the certified L2 gain from the channels ``w = [d; f''; u_s; f; 1]`` to the
  fault-estimation error (``max_k gain_k`` of the design's ``bounds.fault_error``; dropped when the base
  design has none).

The chosen design (:func:`choose`) is a member of the front: among the front members that are
certified (every completed trial is), make tolerant control no worse than none in any window, on the outputs
as a whole and on each output (every FTC ratio measured <= 1, each to :data:`FTC_RESOLUTION`) and keep every
false-alarm ratio below 1 — or, when none does, the first tier of :data:`TIERS` that has members (a ratio above 1
whose interval over the paths holds 1 counting as a tie, as the verdicts judge it; then without the false alarms;
else all of them) — the one with the smallest score of the rule:

- ``balanced`` (default): among the members whose input peak stays within :data:`INPUT_PEAK_ALLOWANCE`
  x the base's and whose saturation rises by at most 1 % of the samples, those better than the base on
  every fault objective (errors, false alarms, each window's FTC ratio: the worst ratio
  ``max_k v_k / max(b_k, 1e-3)`` below 1) first, and of them the one better by the most on the whole
  (the smallest geometric mean of the ratios); when there is none, the one whose worst ratio is
  smallest (the base itself scores 1). The rule picks a design that dominates the base whenever the
  search found one, and of several such the one that gains most, not the one closest to the base;
- ``fault-error``: the largest fault error; ``false-alarm``: the largest false-alarm ratio;
  ``ftc``: the windows' FTC ratios as judged (a tie counts 1), worst first, compared in turn (a design whose
  tolerant control ties everywhere is not better than one that ties in one window and helps in another);
  ``bound``: the smallest certified bound;

ties broken by the balanced score, then by the sum of all objectives relative to the base's (the
bound among them). The bound is not in the balanced score: that score is the issue's measured table.
"""

from __future__ import annotations

import hashlib
import json
import math
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from .._keywords import with_keywords
from ..errors import ParameterError
from ..verdicts import FALSE_ALARM, WORSE_THAN_NONE, judged_ftc_ratio, judged_ftc_ratios_per_output
from ._evaluate import evaluate
from ._options import RULES as RULES
from ._options import TuneOptions
from ._space import Space, space_for

__all__ = ["tune", "TuneResult", "Record", "choose", "pareto_front", "RULES"]  # public: docs/api.md

#: trials asked from the sampler before any of them is told (also the tasks sent to a cluster at once)
BATCH = 4
#: paths per candidate unless asked (or the scenario's, when more)
DEFAULT_PATHS = 20
#: objective values for a metric a candidate leaves undefined
UNDEFINED = 1e6
#: floors of the base values the balanced rule divides by, per objective kind
FLOORS = {
    "fault_error": 1e-3,
    "false_alarm": 1e-3,
    "ftc": 1e-3,
    "input_peak": 1e-12,
    "input_saturation": 1e-2,
    "bound": 1e-12,
}
#: the resolution of the FTC ratios the choice compares (tiers and the ``ftc`` rule): the levitation's default
#: design tied in its sensor window to 1.2e-7 (interval above 1: the runs share their paths), and a design whose
#: tolerant control did next to nothing (0.99997 and 0.99995) was chosen over its 0.709 in the actuator window
FTC_RESOLUTION = 1e-3
#: the objectives of the balanced rule's score (the issue's table: errors, false alarms, FTC ratio per window)
FAULT_KINDS = ("fault_error", "false_alarm", "ftc")
#: the balanced rule takes designs whose input peak is at most this multiple of the base design's
INPUT_PEAK_ALLOWANCE = 1.5


@dataclass(frozen=True)
class Record:
    """One trial: its knobs, and for a completed one its design's params, metrics, design document
    (JSON) and objective values; for a failed one the reason."""

    number: int
    knobs: dict
    state: str
    params: dict | None = None
    metrics: dict | None = None
    design: str | None = None
    values: tuple | None = None
    reason: str | None = None


@dataclass(frozen=True)
class TuneResult:
    """What :func:`tune` found. ``front`` and ``chosen`` index ``records`` (trial numbers)."""

    plant: str
    objectives: tuple
    records: tuple
    front: tuple
    chosen: int
    rule: str
    tier: str
    seed: int
    paths: int
    space: dict
    wall_s: float
    limits: tuple = field(default_factory=tuple)

    @property
    def baseline(self) -> Record:
        return self.records[0]

    def record(self, number: int) -> Record:
        return self.records[number]


def _window_tag(w: dict) -> str:
    return f"{w['fault']}@{w['start']:g}"


def objectives_for(
    base_metrics: dict, fault_names, has_limits: bool
) -> tuple[tuple, Callable[[dict], tuple]]:
    """The objective names defined at the base design, and the function from a metrics document to
    their values (``UNDEFINED`` where a candidate leaves one undefined)."""
    names, getters = [], []
    for key, kind in (("fault_rel_rms_error", "fault_error"), ("false_alarm_peak", "false_alarm")):
        for j, f in enumerate(fault_names):
            v = (base_metrics.get(key) or [None] * len(fault_names))[j]
            if v is not None:
                names.append(f"{kind}[{f}]")
                getters.append(
                    lambda m, key=key, j=j: (m.get(key) or [])[j] if j < len(m.get(key) or []) else None
                )
    for k, w in enumerate(base_metrics.get("windows") or []):
        if w.get("ftc_true_ratio") is not None:
            names.append(f"ftc[{_window_tag(w)}]")
            getters.append(lambda m, k=k: m["windows"][k]["ftc_true_ratio"])
    base_peak = np.asarray(base_metrics["input_peak"], float)
    if np.any(base_peak > 0):
        names.append("input_peak")
        getters.append(lambda m: float(max(p / b for p, b in zip(m["input_peak"], base_peak) if b > 0)))
    if has_limits:
        names.append("input_saturation")
        getters.append(lambda m: float(max(m["input_saturation"])) if m["input_saturation"] else 0.0)
    if base_metrics.get("fault_error_bound") is not None:
        names.append("bound[fault_error]")
        getters.append(lambda m: m.get("fault_error_bound"))

    def values(m: dict) -> tuple:
        out = []
        for g in getters:
            v = g(m)
            out.append(UNDEFINED if v is None or not math.isfinite(v) else float(v))
        return tuple(out)

    return tuple(names), values


def pareto_front(values: list[tuple]) -> list[int]:
    """Indices of the non-dominated vectors (all objectives minimised); of equal vectors the first."""
    V = np.asarray(values, float)
    keep = []
    for i in range(len(V)):
        le = np.all(V <= V[i], axis=1)
        lt = np.any(V < V[i], axis=1)
        dominated = np.any(le & lt)
        duplicate = np.any(np.all(V[:i] == V[i], axis=1)) if i else False
        if not dominated and not duplicate:
            keep.append(i)
    return keep


def _kind(name: str) -> str:
    return name.split("[")[0]


def _ratios(values: tuple, base: tuple, names: tuple, kinds=FAULT_KINDS) -> list[float]:
    return [v / max(b, FLOORS[_kind(n)]) for v, b, n in zip(values, base, names) if _kind(n) in kinds]


def balanced_score(values: tuple, base: tuple, names: tuple) -> float:
    """The worst fault objective (errors, false alarms, each window's FTC ratio) relative to the base's:
    below 1 exactly when the candidate is better than the base on every one of them."""
    return max(_ratios(values, base, names), default=0.0)


def _log_mean(ratios: list[float]) -> float:
    """The mean of the logarithms (the geometric mean's logarithm; 0 for none)."""
    return float(np.mean(np.log(np.maximum(ratios, 1e-300)))) if ratios else 0.0


def _within_inputs(values: tuple, base: tuple, names: tuple) -> bool:
    """The inputs' allowance of the balanced rule: peak <= INPUT_PEAK_ALLOWANCE x the base's, and
    saturation at most 1 % of the samples above the base's."""
    v, b = dict(zip(names, values)), dict(zip(names, base))
    return (v.get("input_peak", 0.0) <= INPUT_PEAK_ALLOWANCE * b.get("input_peak", 1.0)
            and v.get("input_saturation", 0.0) <= b.get("input_saturation", 0.0) + 0.01)  # fmt: skip


def _admissible(m: dict) -> tuple[bool, bool, bool]:
    """(no window's tolerant control worse than none, on the outputs as a whole or on any one output, as the
    verdicts judge it; every one of those ratios measured at most 1; every false-alarm ratio < 1): the
    thresholds and the rule of :mod:`fte_casadi.verdicts` (a ratio above 1 whose interval over the paths holds 1
    is a tie, not worse), the ratios to :data:`FTC_RESOLUTION`."""
    windows = m.get("windows") or []
    judged = _judged(m) + _rounded(v for w in windows for v in judged_ftc_ratios_per_output(w))
    measured = _rounded(v for w in windows for v in (w.get("ftc_true_ratio"), *(w.get("ftc_true_ratio_per_output")
                                                                                 or [])))  # fmt: skip
    fa = all(v < FALSE_ALARM for v in m.get("false_alarm_peak") or [] if v is not None)
    return (all(v <= WORSE_THAN_NONE for v in judged), all(v <= WORSE_THAN_NONE for v in measured), fa)


def _judged(m: dict) -> list[float]:
    """Every window's FTC ratio as the verdicts judge it (:func:`fte_casadi.verdicts.judged_ftc_ratio`), rounded to
    :data:`FTC_RESOLUTION`: a design is not chosen, nor left out, for less."""
    return _rounded(judged_ftc_ratio(w) for w in m.get("windows") or [])


def _rounded(values) -> list[float]:
    return [round(v / FTC_RESOLUTION) * FTC_RESOLUTION for v in values if v is not None]


#: the tiers of :func:`choose`, first to last: (what its members do, which of :func:`_admissible`'s three they
#: meet); a tie (a ratio above 1 whose interval holds 1) counts as not worse than none, but a design that measures
#: no ratio above 1 is taken first
TIERS = (
    ("tolerant control measured no worse than none in any window nor on any output (every ratio <= 1), and every "
     "false-alarm ratio < 1", (True, True, True)),
    ("tolerant control not worse than none in any window nor on any output (a ratio above 1 whose interval holds 1 "
     "a tie; no front member measures every ratio <= 1), and every false-alarm ratio < 1", (True, False, True)),
    ("tolerant control measured no worse than none in any window nor on any output (every ratio <= 1; no front "
     "member keeps every false-alarm ratio below 1)", (True, True, False)),
    ("tolerant control not worse than none in any window nor on any output (a ratio above 1 whose interval holds 1 "
     "a tie; no front member measures every ratio <= 1, nor keeps every false-alarm ratio below 1)",
     (True, False, False)),
    ("none of the front keeps tolerant control from being worse than none in every window and on every output",
     (False, False, False)),
)  # fmt: skip


def choose(records: list[Record], front: list[int], names: tuple, rule: str) -> tuple[int, str]:
    """The chosen trial number among ``front`` (trial numbers of completed records) by ``rule``, and
    which tier it came from (see the module docstring)."""
    if rule not in RULES:
        raise ParameterError(f"unknown objective rule {rule!r}; choose one of {', '.join(RULES)}")
    base = records[0].values
    cands = [records[k] for k in front]
    tier, pool = TIERS[-1][0], cands
    admissible = {r.number: _admissible(r.metrics) for r in cands}  # once per member, not once per tier
    for name, needs in TIERS:
        ok = [r for r in cands if all(have or not need for have, need in zip(admissible[r.number], needs))]
        if ok:
            tier, pool = name, ok
            break
    if rule == "balanced":
        kept = [r for r in pool if _within_inputs(r.values, base, names)]
        if kept:
            pool = kept
        else:
            tier += "; no member within the inputs' allowance"

    def key(r: Record):
        bal = balanced_score(r.values, base, names)
        v = dict(zip(names, r.values))
        if rule == "balanced":
            # better than the base on every fault objective: the one better by the most on the whole (the
            # geometric mean of the ratios); else the smallest worst ratio
            main = (0, _log_mean(_ratios(r.values, base, names))) if bal < 1 else (1, bal)
        elif rule == "fault-error":
            main = max((x for n, x in v.items() if n.startswith("fault_error")), default=bal)
        elif rule == "false-alarm":
            main = max((x for n, x in v.items() if n.startswith("false_alarm")), default=bal)
        elif rule == "bound":
            main = v.get("bound[fault_error]", bal)
        else:  # the windows' judged ratios, worst first: a tie at 1 everywhere is not better than 0.7 and a tie
            main = tuple(sorted(_judged(r.metrics), reverse=True)) or (bal,)
        return (main, bal, sum(_ratios(r.values, base, names, tuple(FLOORS))), r.number)

    return min(pool, key=key).number, tier


def _runner(scheduler):
    """``run(tasks) -> results`` in order: in this process, or on the cluster at ``scheduler``."""
    if scheduler is None:
        return (lambda tasks: [evaluate(t) for t in tasks]), (lambda: None)
    from ..sim._cluster import client_for

    client = client_for(scheduler) if isinstance(scheduler, str) else scheduler

    def run(tasks):
        futs = [client.submit(evaluate, t, pure=False, retries=1) for t in tasks]
        return client.gather(futs)

    return run, (client.close if isinstance(scheduler, str) else (lambda: None))


def tune(base_design, plant, scenario, *, trials: int | None = None, seed: int = 0, rule: str = "balanced",
         paths: int | None = None, scheduler=None, sigma_sup: float | None = None, base_is_given: bool = False,
         progress: Callable[[int, int], None] | None = None, storage: str | None = None,
         resume: bool = False, options: TuneOptions | None = None) -> TuneResult:  # fmt: skip
    """Search the knobs of ``base_design`` for designs that estimate and tolerate the faults of ``scenario``.

    Parameters
    ----------
    base_design : Design
        Trial 0 and the centre of the search space (:func:`~fte_casadi.tune._space.space_for`).
    plant, scenario
        The nonlinear plant and the experiment every candidate is simulated on (same seed, same paths).
    options : TuneOptions, optional
        How the search goes: ``trials`` (required, here or as a keyword), ``seed``, ``rule``, ``paths``,
        ``scheduler``, ``sigma_sup``, ``base_is_given``, ``progress``, ``storage``, ``resume``
        (:class:`~fte_casadi.tune.TuneOptions` says what each does and its default). Each is also a keyword
        argument of this function; a keyword given with a value other than its default changes the record's.

    A resumed search (``resume`` with a ``storage`` that holds one) takes its finished trials as they are, runs
    the trials that were running again, and goes on to ``trials`` in all with the sampler's random state as it
    was, so the trials are those an uninterrupted run asks. The run must have the same plant, base design, seed
    and paths.
    """
    import optuna

    given = dict(trials=trials, seed=seed, rule=rule, paths=paths, scheduler=scheduler, sigma_sup=sigma_sup,
                 base_is_given=base_is_given, progress=progress, storage=storage, resume=resume)  # fmt: skip
    if options is not None and trials is None:
        del given["trials"]
    o = with_keywords(TuneOptions, options, given)
    paths = int(o.paths or max(scenario.paths, DEFAULT_PATHS))
    t0 = time.perf_counter()
    search = _Search(optuna, base_design, plant, scenario, o, paths)
    level = optuna.logging.get_verbosity()
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    try:
        search.run(t0)
    finally:
        optuna.logging.set_verbosity(level)
        search.close()
    return search.result(t0)


class _Search:
    """One search of :func:`tune`: trial 0 (fresh, or as a stored search kept it), the trials asked in batches
    and told back in trial order, the records they give."""

    def __init__(self, optuna, base_design, plant, scenario, o: TuneOptions, paths: int):
        from ..sim._cluster import plant_bytes

        self.optuna, self.base_design, self.plant, self.scenario, self.o = (
            optuna,
            base_design,
            plant,
            scenario,
            o,
        )
        self.paths, self.trials = paths, o.trials
        self.fixed = {"delta": float(base_design.params.delta)}
        self.common = {
            "plant": plant_bytes(plant), "scenario": scenario.to_dict(), "variant": base_design.variant,
            "solver": base_design.solver, "sample_time": base_design.observer.sample_time or scenario.dt,
            "initial_state": None if base_design.x0 is None else [float(v) for v in base_design.x0],
            "plant_spec": base_design.plant_spec, "paths": paths, "seed": o.seed, "vertices": base_design.vertices,
        }  # fmt: skip
        self.run_tasks, self.close = _runner(o.scheduler)
        self.records: list[Record] = []
        self.wall0 = 0.0

    def run(self, t0: float) -> None:
        """Trial 0, then the other trials to ``trials`` in all (continuing a stored search when asked)."""
        optuna, o = self.optuna, self.o
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            sampler = optuna.samplers.TPESampler(seed=o.seed, multivariate=True,
                                                 n_startup_trials=max(4, min(12, self.trials // 4)))  # fmt: skip
        key = _fingerprint(self.plant, self.scenario, self.base_design, o.seed, self.paths)
        study = _stored_study(optuna, o.storage, sampler, key) if o.resume and o.storage is not None else None
        sigma_sup, base_task, out0 = self._trial0(study)
        self.names, self.values_of = objectives_for(
            out0["metrics"], list(self.plant.fault_names), self.plant.input_limits is not None
        )
        self.e_scale = out0["e_scale"]
        self.space: Space = space_for(self.base_design, sigma_sup,
                                      *_base_knobs(self.base_design, base_task, self.e_scale))  # fmt: skip
        if study is None:
            self._start(sampler, key, sigma_sup, out0)
        else:
            self.study = study
            self._resume()
        while len(self.records) < self.trials:
            self._batch(sampler, t0)
        if o.storage is not None:
            self.study.set_user_attr("wall_s", self.wall0 + time.perf_counter() - t0)

    def _trial0(self, study) -> tuple[float | None, dict, dict]:
        """``(sigma_sup, trial 0's task, its outcome)``: evaluated afresh, or as the stored search kept it."""
        sigma_sup = self.o.sigma_sup
        if study is not None:
            sigma_sup = study.user_attrs.get("sigma_sup")
        elif sigma_sup is None:
            sigma_sup = _sigma_sup(self.plant, self.base_design)
        base_task = dict(self.common, knobs=space_for(self.base_design, sigma_sup).base | self.fixed, e_scale=None,
                         design=self.base_design.to_json())  # fmt: skip
        if study is not None:
            return sigma_sup, base_task, {"state": "ok", "e_scale": study.user_attrs["e_scale"],
                                          **study.user_attrs["trial-0"]}  # fmt: skip
        out0 = self.run_tasks([base_task])[0]
        if out0["state"] != "ok":
            raise ParameterError(
                f"the base design of {self.plant.name} cannot be evaluated ({out0['reason']}); tune from a design "
                "that certifies and simulates (fte design, fte simulate)"
            )
        return sigma_sup, base_task, out0

    def _start(self, sampler, key: dict, sigma_sup, out0: dict) -> None:
        """A fresh search: the study, trial 0 told first, the local steps around it enqueued."""
        optuna, space = self.optuna, self.space
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            study = self.study = _new_study(optuna, self.o.storage, sampler, len(self.names))
            study.set_user_attr("fte", key)
            study.set_user_attr("sigma_sup", sigma_sup)
            study.set_user_attr("e_scale", self.e_scale)
            study.enqueue_trial(space.base)
            t = study.ask()
            space.suggest(t)
            for knobs in space.local_steps(self.trials - 1):
                study.enqueue_trial(knobs)
        self.told(t, dict(space.base), out0)

    def _resume(self) -> None:
        """A stored search: the finished trials as they are; those that were running, again."""
        self.wall0 = float(self.study.user_attrs.get("wall_s", 0.0))
        running = _restore(self.optuna, self.study, self.records, self.space)
        if self.o.progress:
            self.o.progress(len(self.records), self.trials)
        for (number, kn), out in zip(running, self.evaluated([kn for _, kn in running])):
            self.told(number, kn, out)

    def _batch(self, sampler, t0: float) -> None:
        """Up to :data:`BATCH` trials asked, evaluated together and told back in trial order."""
        optuna, study = self.optuna, self.study
        k = min(BATCH, self.trials - len(self.records))
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", optuna.exceptions.ExperimentalWarning)
            asked = [study.ask() for _ in range(k)]
            knobs = [self.space.suggest(t) for t in asked]
        if self.o.storage is not None:  # for a resumed run: the knobs, the sampler's state after drawing them
            for t, kn in zip(asked, knobs):
                study.set_user_attr(f"trial-{t.number}", {"knobs": kn})
            study.set_user_attr("sampler", _random_states(sampler))
            study.set_user_attr("wall_s", self.wall0 + time.perf_counter() - t0)
        for t, kn, out in zip(asked, knobs, self.evaluated(knobs)):
            self.told(t, kn, out)

    def told(self, t, kn: dict | None, out: dict) -> None:
        """Tell optuna (and its storage) how trial ``t`` (a trial or its number) ended; record it."""
        study = self.study
        number = t if isinstance(t, int) else t.number
        if out["state"] == "ok":
            v = self.values_of(out["metrics"])
            study.set_user_attr(
                f"trial-{number}", {k: out[k] for k in ("params", "metrics", "design")} | {"knobs": kn}
            )
            study.tell(t, list(v))
            self.records.append(Record(number, kn, "ok", out["params"], out["metrics"], out["design"], v))
        else:
            study.set_user_attr(f"trial-{number}", {"knobs": kn, "reason": out["reason"]})
            study.tell(t, state=self.optuna.trial.TrialState.FAIL)
            self.records.append(Record(number, kn or {}, "fail", reason=out["reason"]))
        if self.o.progress:
            self.o.progress(len(self.records), self.trials)

    def evaluated(self, knobs: list) -> list[dict]:
        """The outcome of each trial of ``knobs`` (None: interrupted before its knobs were drawn)."""
        todo = [kn for kn in knobs if kn is not None]
        outs = iter(self.run_tasks([dict(self.common, knobs=kn | self.fixed, e_scale=self.e_scale, design=None)
                                    for kn in todo]))  # fmt: skip
        return [next(outs) if kn is not None else {"state": "fail", "reason": "interrupted before its knobs "
                "were drawn"} for kn in knobs]  # fmt: skip

    def result(self, t0: float) -> TuneResult:
        """The records in trial order, their Pareto front and the chosen design."""
        records, plant = self.records, self.plant
        records.sort(key=lambda r: r.number)
        done = [r for r in records if r.state == "ok"]
        front = [done[i].number for i in pareto_front([r.values for r in done])]
        chosen, tier = choose(records, front, self.names, self.o.rule)
        return TuneResult(plant=plant.name, objectives=self.names, records=tuple(records), front=tuple(front),
                          chosen=chosen, rule=self.o.rule, tier=tier, seed=self.o.seed, paths=self.paths,
                          space=dict(self.space.ranges), wall_s=self.wall0 + time.perf_counter() - t0,
                          limits=tuple(_limits(done, plant)))  # fmt: skip


#: the name of the study in an optuna storage
STUDY_NAME = "fte-tune"


def _fingerprint(plant, scenario, base_design, seed: int, paths: int) -> dict:
    """What a resumed search must share with the stored one (as JSON gives it back)."""
    sc = hashlib.sha256(json.dumps(scenario.to_dict(), sort_keys=True).encode()).hexdigest()
    doc = {"plant": plant.name, "seed": seed, "paths": paths, "variant": base_design.variant,
           "solver": base_design.solver, "params": base_design.to_dict()["params"], "scenario": sc}  # fmt: skip
    return json.loads(json.dumps(doc))


def _differs(a, b, at: str = "") -> str | None:
    """The first key where ``a`` and ``b`` differ (floats to 1e-9), or None."""
    if isinstance(a, dict) and isinstance(b, dict):
        for k in sorted(set(a) | set(b)):
            d = _differs(a.get(k), b.get(k), f"{at}.{k}" if at else k)
            if d:
                return d
        return None
    if isinstance(a, float) and isinstance(b, (int, float)) and not isinstance(b, bool):
        return None if math.isclose(a, b, rel_tol=1e-9, abs_tol=0.0) else at
    return None if a == b else at


def _new_study(optuna, storage, sampler, nobj: int):
    try:
        return optuna.create_study(directions=["minimize"] * nobj, sampler=sampler, storage=storage,
                                   study_name=STUDY_NAME)  # fmt: skip
    except optuna.exceptions.DuplicatedStudyError:
        raise ParameterError(f"{storage} holds a search already: continue it (fte tune --resume) or remove it "
                             "to start afresh") from None  # fmt: skip


def _stored_study(optuna, storage: str, sampler, key: dict):
    """The search kept in ``storage``, its sampler's random state restored; None when there is none
    to continue (no study, or one whose trial 0 never finished: removed)."""
    try:
        study = optuna.load_study(study_name=STUDY_NAME, storage=storage, sampler=sampler)
    except KeyError:
        return None
    attrs = study.user_attrs
    first = study.get_trials(deepcopy=False)[:1]
    if not first or first[0].state != optuna.trial.TrialState.COMPLETE or "trial-0" not in attrs:
        optuna.delete_study(study_name=STUDY_NAME, storage=storage)
        return None
    where = _differs(attrs.get("fte") or {}, key)
    if where:
        was = (attrs.get("fte") or {}).get(where.split(".")[0])
        raise ParameterError(
            f"the search kept in {storage} differs from this one in {where} (it was run with {was!r}): continue it "
            "with the same target, --seed and --paths, or remove it to start afresh"
        )
    _set_random_states(sampler, attrs.get("sampler"))
    return study


def _restore(optuna, study, records: list, space: Space) -> list[tuple[int, dict | None]]:
    """Append the stored trials that finished to ``records``; return those that were running as
    ``(number, knobs)`` (knobs None when they were never drawn)."""
    State = optuna.trial.TrialState
    attrs = study.user_attrs
    running = []
    for ft in study.get_trials(deepcopy=False, states=(State.COMPLETE, State.FAIL, State.RUNNING)):
        kept = attrs.get(f"trial-{ft.number}") or {}
        kn = kept.get("knobs")
        if ft.state == State.COMPLETE:
            records.append(Record(ft.number, kn, "ok", kept["params"], kept["metrics"], kept["design"],
                                  tuple(ft.values)))  # fmt: skip
        elif ft.state == State.FAIL:
            records.append(Record(ft.number, kn or {}, "fail", reason=kept.get("reason", "failed")))
        else:
            if kn is None:
                try:
                    kn = space.suggest(optuna.trial.FixedTrial(ft.params))
                except ValueError:
                    kn = None
            running.append((ft.number, kn))
    return running


def _random_generators(obj, path: str = "sampler", depth: int = 0) -> dict:
    """The numpy generators inside an optuna sampler, by attribute path (optuna keeps them in
    ``LazyRandomState`` objects); a resumed search restores their states to ask the same trials."""
    if isinstance(obj, np.random.RandomState):
        return {path: obj}
    if isinstance(getattr(type(obj), "rng", None), property):
        return {path: obj.rng}
    if depth >= 3 or isinstance(obj, type) or not hasattr(obj, "__dict__"):
        return {}
    out: dict = {}
    for k, v in sorted(vars(obj).items()):
        out |= _random_generators(v, f"{path}.{k}", depth + 1)
    return out


def _random_states(sampler) -> dict:
    out = {}
    for path, g in _random_generators(sampler).items():
        name, keys, pos, has_gauss, cached = g.get_state()
        out[path] = [name, [int(v) for v in keys], int(pos), int(has_gauss), float(cached)]
    return out


def _set_random_states(sampler, states: dict | None) -> None:
    """Restore :func:`_random_states`; where the sampler holds other generators (another optuna),
    the resumed search goes on from the seed's state instead (other trials than an uninterrupted run)."""
    found = _random_generators(sampler)
    if not states or set(states) != set(found):
        return
    for path, g in found.items():
        name, keys, pos, has_gauss, cached = states[path]
        g.set_state((name, np.asarray(keys, dtype=np.uint32), pos, has_gauss, cached))


def _base_knobs(base_design, base_task: dict, e_scale: float | None) -> tuple[float, float | None]:
    """The base design's ``alpha_scale`` (1 when its alpha is the default rate; else its alpha over the
    default rate at its other knobs, one design more) and ``boundary_layer_rel`` (None without one)."""
    from ._evaluate import default_alpha

    scale = 1.0
    alpha = base_design.observer.alpha
    if alpha is not None and base_design.observer.alpha_max is None:  # alpha was set, not found
        a0 = default_alpha(base_task)
        if a0:
            scale = float(alpha) / a0
    phi = base_design.params.boundary_layer
    rel = None
    if phi is not None and e_scale:
        rel = float(phi) / (float(np.linalg.norm(base_design.N, 2)) * float(e_scale))
    return scale, rel


def _sigma_sup(plant, base_design) -> float | None:
    """The largest sigma (45) allows for any gamma at the base gamma1 (None when none or on failure)."""
    from ..design import augment, sigma_max
    from ..errors import FteError
    from ..ts import derive

    try:
        ts = derive(plant, vertices=base_design.vertices)
        aug = augment(ts.local_models, ts.C, ts.Df)
        return sigma_max(aug, None, float(base_design.params.gamma1), base_design.solver)[0]
    except FteError:
        return None


def _limits(done, plant) -> list[str]:
    """The windows where no certified candidate makes tolerant control better
    than none, and the faults whose false alarms none keeps below 1, with their structural causes
    (:func:`fte_casadi.design._limits.explain_metrics`, at the candidate closest to succeeding)."""
    from ..design import Design, explain_metrics

    if not done:
        return []
    nwin = len(done[0].metrics.get("windows") or [])
    out = []
    for k in range(nwin):
        best = min(done, key=lambda r: r.metrics["windows"][k]["ftc_true_ratio"] or math.inf)
        if (best.metrics["windows"][k]["ftc_true_ratio"] or math.inf) >= WORSE_THAN_NONE:
            d = Design.from_dict(json.loads(best.design))
            out += [f"no certified candidate makes tolerant control better than none here (best: trial {best.number}); "
                    + s for s in explain_metrics(d, best.metrics, windows=[k], faults=[])]  # fmt: skip
    for j in range(len(plant.fault_names)):
        vals = [(r.metrics["false_alarm_peak"] or [None] * (j + 1))[j] for r in done]
        if all(v is None for v in vals):
            continue
        i = int(np.argmin([math.inf if v is None else v for v in vals]))
        if vals[i] is not None and vals[i] >= 1:
            d = Design.from_dict(json.loads(done[i].design))
            out += [f"no certified candidate keeps the false alarms below 1 (best: trial {done[i].number}); " + s
                    for s in explain_metrics(d, done[i].metrics, windows=[], faults=[j])]  # fmt: skip
    return out
