"""``fte simulate`` and ``fte sweep``: Monte Carlo of the closed loop, once or over a grid, in words."""

from __future__ import annotations

import json
import textwrap
from pathlib import Path

import click
import numpy as np

from .._rounding import ratio_text as ratio
from ..errors import ParameterError
from ._common import _check_paths, _check_seed, _guard, _outputs, _positive, _writable_target
from ._targets import _allow_option, _design_or_plant, _need_plant, _plant_option

#: the options fte simulate and fte sweep share
_seed_option = click.option(
    "--seed", type=int, default=0, show_default=True, help="Seed of the random generator."
)
_scheduler_option = click.option(
    "--scheduler", help="Address of a dask.distributed scheduler: run the paths on its workers."
)
_fast_math_option = click.option("--fast-math", "fast_math", is_flag=True,
              help="Fast mode: fused multiply-adds and a vector math library (equal to the default within "
                   "the tolerance of docs/simulation.md; the same numbers for any split of the paths).")  # fmt: skip


def _g3(x) -> str:
    return "n/a" if x is None else f"{x:.3g}"


def _fmt_list(v, fmt=_g3) -> str:
    """Numbers in brackets, each by ``fmt`` (FTC ratios: :func:`fte_casadi._rounding.ratio_text`)."""
    return "[" + ", ".join(fmt(x) for x in v) + "]"


def _noise_option(noise: str | None) -> list[float] | None:
    """``--measurement-noise`` as standard deviations (None: not given), each a finite number >= 0."""
    if noise is None:
        return None
    if not noise.strip():
        raise ParameterError("--measurement-noise is empty: give one standard deviation per output, comma-separated "
                             "(e.g. 0.01,0,0.02), or leave the option out")  # fmt: skip
    try:
        stds = [float(v) for v in noise.split(",")]
    except ValueError:
        raise ParameterError(
            f"--measurement-noise {noise!r}: give one standard deviation per output, comma-separated (e.g. 0.01,0,0.02)"
        ) from None
    for v in stds:
        _positive("measurement-noise", v, allow_zero=True)
    return stds


def _with_noise(scenario, stds: list[float] | None, d):
    """The scenario with ``--measurement-noise`` when given: one standard deviation per output of ``d``, each at
    most the width of the range the generated C accepts for that output (a larger one is no measurement, and the
    run's estimates would overflow)."""
    if stds is None:
        return scenario
    import dataclasses

    from ..codegen import output_range

    p = int(d.dims.p)
    names = list((d.names or {}).get("outputs") or [f"y{k + 1}" for k in range(p)])
    if len(stds) != p:
        raise ParameterError(f"--measurement-noise has {len(stds)} entries; the plant has {p} outputs "
                             f"({', '.join(names)}): give one standard deviation per output")  # fmt: skip
    rng = output_range(d)
    for k, v in enumerate(stds):
        width = float(rng["hi"][k] - rng["lo"][k])
        if v > width:
            raise ParameterError(
                f"--measurement-noise: {v:g} for output {names[k]} exceeds the whole range the generated C accepts "
                f"for it ([{rng['lo'][k]:.6g}, {rng['hi'][k]:.6g}], width {width:.6g}): noise that large is no "
                "measurement, and the run's estimates would overflow; give at most that"
            )
    return dataclasses.replace(scenario, measurement_noise=tuple(stds))


def _nonfinite(m, path: str = "") -> list[str]:
    """The keys of a metrics document that hold a NaN or an infinity (a result is never a non-finite number)."""
    if isinstance(m, dict):
        return [p for k, v in m.items() for p in _nonfinite(v, f"{path}.{k}" if path else str(k))]
    if isinstance(m, (list, tuple)):
        return [p for k, v in enumerate(m) for p in _nonfinite(v, f"{path}[{k}]")]
    if isinstance(m, float) and not np.isfinite(m):
        return [path]
    return []


def _summary(plant: str, m: dict) -> str:
    """The metrics document in words (docs/interface.md gives each formula)."""
    lines = [
        f"{plant}: {m['paths']} paths x 3 runs, T = {m['T']:g}, dt = {m['dt']:g}, seed {m['seed']}, {m['wall_s']:.2f} s",
        f"  allowances: start-up transient {m['transient']:.4g}, after each window {m['settle_after']:.4g}",
        f"  state RMS error (t >= transient, FTC run): {_fmt_list(m['state_rms_error'])}",
        f"  fault error, relative RMS over whole windows: {_fmt_list(m['fault_rel_rms_error'])} "
        f"(settled part, each window minus its first 20 %: {_fmt_list(m['fault_rel_rms_error_settled'])})",
        f"  false alarms, estimate outside its windows: peak / fault's peak {_fmt_list(m['false_alarm_peak'])}, "
        f"relative RMS {_fmt_list(m['false_alarm_rel_rms'])}; without the allowances (raw) "
        f"{_fmt_list(m.get('false_alarm_peak_raw') or [])}: in the start-up "
        f"{_fmt_list(m.get('false_alarm_peak_startup') or [])}, after a window "
        f"{_fmt_list(m.get('false_alarm_peak_after_window') or [])}",
        f"  tolerant control, true outputs C x (ftc_true_ratio, < 1: better than none): {ratio(m['ftc_true_ratio'])}"
        f"{_ival(m.get('ftc_true_ratio_interval'), fmt=ratio)}; compensated reading yc (ftc_compensated_ratio, estimation only): "
        f"{_num(m['ftc_compensated_ratio'])}",
    ]
    for e in m.get("detection") or []:
        lines.append(
            f"  detection of {e['fault']}: threshold {_num(e['threshold'])} from t = {_num(e.get('steady_from'), '.4g')}"
            f" ({len(e.get('startup_thresholds') or [])} start-up blocks with their own), calibrated on "
            f"{e.get('calibration_paths')} fault-free paths ({_num(e.get('calibration_hours'))} path-hours, "
            f"{e.get('calibration_method')}): it promises {_ival(e.get('false_alarm_rate_interval'), '')} false alarms "
            f"per unit time (asked {_num(e['false_alarm_rate_asked'])}); measured {_num(e['false_alarm_rate'])}"
            f"{_ival(e.get('false_alarm_rate_measured_interval'))} on this run's fault-free paths, "
            f"{_num(e.get('false_alarm_rate_ftc_run'))}{_ival(e.get('false_alarm_rate_ftc_run_interval'))} outside its "
            "windows in the faulty run"
        )
    for s in m.get("detectability") or []:
        for c in s["curves"]:
            mdf = c["min_detectable_fault"]
            lines.append(
                f"  smallest {c['fault']} detected on {100 * s['target']:g} % of {s['paths']} paths within "
                f"{_num(c['delay'])} ({s.get('label')}): "
                + (f"{mdf:.3g} (factor {c['min_detectable_factor']:.3g} of the scenario's)" if mdf is not None
                   else f"n/a ({c['why']})")
            )  # fmt: skip
    if m.get("measurement_noise") is not None:
        lines.append(f"  measurement noise (std per output): {_fmt_list(m['measurement_noise'])}")
    lines.append(f"  samples outside the plant's region: {100 * m['outside_region']:.2g} %")
    if m.get("outside_c_range_paths") is not None:
        first = m.get("outside_c_range_first")
        lines.append(
            "  measurements outside the range the generated C accepts (there its step returns 3): "
            f"{100 * m['outside_c_range']:.2g} % of the samples, on {100 * m['outside_c_range_paths']:.3g} % of the paths"
            + (f", first at t = {first:.6g}" if first is not None else "")
        )
    lines.append(f"  inputs at a limit (FTC run): {_fmt_list(m['input_saturation'])}")
    return "\n".join(lines)


def _num(v, fmt: str = ".3g") -> str:
    return "n/a" if v is None else format(v, fmt)


def _ival(iv, lead: str = " ", fmt=_g3) -> str:
    """A 95 % interval over the paths, ``[lo, hi]`` (each end by ``fmt``), or nothing."""
    return "" if not iv else f"{lead}[{fmt(iv[0])}, {fmt(iv[1])}]"


def _window_lines(m: dict) -> list[str]:
    """Per fault window: its estimation error, settling, detection and tolerant-control figures."""
    out = []
    for w in m.get("windows", []):
        det = w.get("detection_delay")
        miss = w.get("missed_detections")
        detected = (
            ""
            if miss is None
            else f"; detected on {_num(w.get('detection_probability'))}{_ival(w.get('detection_probability_interval'))}"
            f" of the paths ({_num(w.get('detection_probability_within'))} within "
            f"{_num(w.get('detection_delay_allowed'))}), after {_num(det)} on average, missed on {miss}, alarm already "
            f"on at the onset (standing, not a detection) on {w.get('standing_alarm_paths')}"
        )
        out.append(
            f"  window {w['fault']} [{w['start']:g}, {w['stop']:g}): fault error (relative RMS, whole window) "
            f"{_num(w['fault_rel_rms_error'])}{_ival(w.get('fault_rel_rms_error_interval'))}, settled part "
            f"{_num(w.get('fault_rel_rms_error_settled'))}, settling time {_num(w.get('settling_time'))}; FTC true ratio "
            f"{ratio(w.get('ftc_true_ratio'))}{_ival(w.get('ftc_true_ratio_interval'), fmt=ratio)} (per output "
            f"{_fmt_list(w.get('ftc_true_ratio_per_output') or [], ratio)}), compensated {_num(w.get('ftc_compensated_ratio'))}"
            + detected
            + _after_window_text(w.get("after_window"))
        )
    return out


def _after_window_text(a: dict | None) -> str:
    """A window's ``after_window`` figures: tolerant control from the window's end to the next window or the horizon."""
    if not a:
        return ""
    return (f"; after it, [{a['start']:g}, {a['stop']:g}) with no fault in the plant: FTC true ratio "
            f"{ratio(a.get('ftc_true_ratio'))}{_ival(a.get('ftc_true_ratio_interval'), fmt=ratio)} (per output "
            f"{_fmt_list(a.get('ftc_true_ratio_per_output') or [], ratio)}), with the window "
            f"{ratio(a.get('ftc_true_ratio_with_window'))}"
            f"{_ival(a.get('ftc_true_ratio_with_window_interval'), fmt=ratio)}")  # fmt: skip


def _detectability(d, plant, scenario, m: dict, paths: int, seed: int, opts) -> dict:
    """``m`` with the detection probability against each fault's size (``fte simulate --detectability``): with the
    scenario's measurement noise and without it (at the run's step, false-alarm rate, calibration and mode)."""
    from ..sim._detectability import attach, detectability

    kw = dict(paths=max(64, int(paths)), seed=seed, dt=opts.dt, false_alarm_rate=opts.false_alarm_rate,
              calibration_paths=opts.calibration_paths, exact=opts.exact)  # fmt: skip
    sets = [detectability(d, plant, scenario, **kw)]
    if scenario.measurement_noise is not None:
        sets.append(detectability(d, plant, scenario, scales={"measurement_noise_scale": 0.0}, **kw))
    for s in sets:
        s["label"] = "without measurement noise" if s["measurement_noise"] is None or not any(
            s["measurement_noise"]) else "with measurement noise"  # fmt: skip
    return attach(m, sets)


def _warnings(m: dict, inputs, faults=(), outputs=(), units=(), states=(), state_units=()) -> list[str]:
    """The verdicts of :func:`fte_casadi.verdicts.verdicts`, as warnings."""
    from ..verdicts import verdicts

    return ["warning: " + v["text"]
            for v in verdicts(m, inputs, faults, outputs, units, states=states, state_units=state_units)]  # fmt: skip


def _why(d, m: dict) -> list[str]:
    """The structural cause behind a window where tolerant control is worse than none, or behind false
    alarms (:func:`fte_casadi.design._limits.explain_metrics`)."""
    from ..design import explain_metrics

    return ["why (the plant's structure, at this design; `fte tune` searches for a design that does better): " + s
            for s in explain_metrics(d, m)]  # fmt: skip


@click.command()
@click.argument("target", metavar="DESIGN.json|PLANT")
@click.option(
    "--paths", type=int, help="Brownian paths (default: the scenario's, the paper's for built-ins)."
)
@_seed_option
@click.option(
    "--dt", type=float, help="Euler-Maruyama step = controller sample time (default: the scenario's)."
)
@click.option(
    "--plots", "plots", type=click.Path(file_okay=False), help="Write the figures (PNG) into this directory."
)
@click.option(
    "--save", "save", type=click.Path(dir_okay=False),
    help="Save per-path arrays of ALL paths (.npz; memory grows with --paths).",
)  # fmt: skip
@_scheduler_option
@_fast_math_option
@click.option("--measurement-noise", "noise",
              help="Standard deviations of white noise on the outputs, one per output (e.g. 0.01,0,0.02), in the "
                   "outputs' units; overrides the scenario's.")  # fmt: skip
@click.option("--false-alarm-rate", "fa_rate", type=float,
              help="False alarms per unit of the plant's time the detection thresholds are set for "
                   "(default: one per hour of operation).")  # fmt: skip
@click.option("--calibration-paths", "cal_paths", type=int,
              help="Fault-free paths the detection thresholds are calibrated on (default: enough for the false-alarm "
                   "rate asked, within a budget of path-steps).")  # fmt: skip
@click.option("--detectability", "detect_curve", is_flag=True,
              help="Also measure the smallest fault the design detects: per fault the detection probability against "
                   "its size (each fault alone, at least 64 paths), with and without the measurement noise.")  # fmt: skip
@click.option("--accommodate", is_flag=True,
              help="Compensate a fault in the control only while it is detected and isolated (thresholds calibrated "
                   "on fault-free paths at --false-alarm-rate); the C and FMU of --save-design's document do the same.")  # fmt: skip
@click.option("--release", "release", type=float,
              help="With --accommodate: a compensated fault stays compensated until |fhat| / threshold falls below "
                   "this ratio (hysteresis; default 0.5); 1: the memoryless gate.")  # fmt: skip
@click.option(
    "--save-design",
    "save_design",
    type=click.Path(dir_okay=False),
    help="With --accommodate: write the design with its accommodation thresholds (for fte codegen).",
)
@click.option(
    "--no-detection",
    "no_detect",
    is_flag=True,
    help="No detection thresholds (skips the fault-free calibration paths).",
)
@click.option("--json", "as_json", is_flag=True, help="Print the metrics document (JSON) on stdout.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@_plant_option
@_allow_option
@_guard
def simulate(target, paths, seed, dt, plots, save, scheduler, fast_math, noise, fa_rate, cal_paths, detect_curve,
             accommodate, release, save_design, no_detect, as_json, quiet, plant_opt, allow_uncertified):  # fmt: skip
    """Monte Carlo of the closed loop on the nonlinear stochastic plant: per path fault-free,
    faulty without tolerant control, faulty with it."""
    from .._resources import check_paths_memory
    from ..plants import load_plant, load_scenario
    from ..sim import carry_free, save_result
    from ..sim import simulate as run_sim

    stds, release = _check_simulate_flags(paths, seed, dt, fa_rate, noise, release, accommodate, no_detect, save,
                                          save_design, plots)  # fmt: skip
    d, spec = _design_or_plant(
        target, progress=not quiet, plant=plant_opt, allow_uncertified=allow_uncertified
    )
    spec = _need_plant(d, spec, "simulate")
    plant = load_plant(spec)
    scenario = _with_noise(load_scenario(spec), stds, d)
    _check_rate_flags(scenario, dt, fa_rate, cal_paths)
    opts = _simulate_options(dt, quiet, save, scheduler, fast_math, no_detect, fa_rate, cal_paths)
    npaths = paths or scenario.paths
    check_paths_memory(d, scenario, npaths, opts.dt, opts.record_all)
    if accommodate:
        d = _accommodated(d, plant, scenario, npaths, seed, opts, release, save_design)
    res = run_sim(d, plant, scenario, paths=npaths, seed=seed, options=opts)
    m = res.metrics
    _refuse_nonfinite(m)
    carry_free(m, d, plant, scenario, paths=npaths, seed=seed, options=opts)  # a window's tie, told from harm
    if detect_curve and opts.detect:
        m = _detectability(d, plant, scenario, m, npaths, seed, opts)
    if save:
        save_result(res, save)
    figs = []
    if plots:
        from ..plot import write_figures

        figs = write_figures(res, plots)
    _say_simulation(d, plant, res, m, as_json)
    if save:
        click.echo(f"per-path arrays of all {res.paths} paths written to {save}", err=True)
    if figs:
        click.echo(
            f"{len(figs)} figures written to {plots} (over the first {res.recorded_paths} paths)", err=True
        )


def _simulate_options(dt, quiet, save, scheduler, fast_math, no_detect, fa_rate, cal_paths):
    """The one place ``fte simulate``'s flags become the run's :class:`~fte_casadi.sim.SimulateOptions`."""
    from ..sim import SimulateOptions

    return SimulateOptions(dt=dt, progress=not quiet, record_all=bool(save), scheduler=scheduler,
                           exact=not fast_math, detect=not no_detect, false_alarm_rate=fa_rate,
                           calibration_paths=cal_paths)  # fmt: skip


def _check_simulate_flags(paths, seed, dt, fa_rate, noise, release, accommodate, no_detect, save, save_design,
                          plots):  # fmt: skip
    """Refuse, before any work, flags that do not go together or are out of range; return the measurement
    noise's standard deviations (None: not given) and the gate's release ratio (default 0.5)."""
    _check_paths(paths)
    _check_seed(seed)
    if dt is not None:
        _positive("dt", dt)
    _positive("false-alarm-rate", fa_rate)
    stds = _noise_option(noise)
    if release is not None and not accommodate:
        raise ParameterError("--release is the hysteresis of --accommodate's gate: give --accommodate, or leave "
                             "--release out")  # fmt: skip
    release = 0.5 if release is None else release
    if not (0 < release <= 1):
        raise ParameterError(f"--release must be in (0, 1] (1: no hysteresis); got {release}")
    if fa_rate is not None and no_detect and not accommodate:
        raise ParameterError("--false-alarm-rate sets the detection thresholds, and --no-detection asks for none: "
                             "give one of them")  # fmt: skip
    if save_design and not accommodate:
        raise ParameterError(
            "--save-design writes the design with its accommodation thresholds: give --accommodate"
        )
    if save and save_design and Path(save).resolve() == Path(save_design).resolve():
        raise ParameterError(f"--save and --save-design name the same file {save}: the result would replace the "
                             "design; give two file names")  # fmt: skip
    if save:
        _writable_target(save, "--save", "result.npz")
    if save_design:
        _writable_target(save_design, "--save-design", "design.json")
    _outputs(save, plots, save_design)
    return stds, release


def _check_rate_flags(scenario, dt, fa_rate, cal_paths) -> None:
    """Refuse ``--calibration-paths`` below 2 and a ``--false-alarm-rate`` of a false alarm per sample or more."""
    if cal_paths is not None and cal_paths < 2:
        raise ParameterError(f"--calibration-paths must be at least 2; got {cal_paths}")
    step = float(dt if dt is not None else scenario.dt)
    if fa_rate is not None and not fa_rate * step < 1:
        raise ParameterError(
            f"--false-alarm-rate {fa_rate:g} asks for at least one false alarm per sample (the step is {step:g}): a "
            f"rate is alarms per unit of the plant's time, below 1 / step = {1 / step:g}; the default is one per hour"
        )


def _accommodated(d, plant, scenario, paths: int, seed: int, opts, release: float, save_design):
    """``--accommodate``: the design with its gate, thresholds calibrated at the run's false-alarm rate; written to
    ``--save-design`` when given."""
    from ..sim import accommodated

    d = accommodated(d, plant, scenario, paths=paths, seed=seed, false_alarm_rate=opts.false_alarm_rate,
                     dt=opts.dt, release=release, calibration_paths=opts.calibration_paths)  # fmt: skip
    click.echo(f"note: {d.status[-1]}", err=True)
    if save_design:
        d.save(save_design)
        click.echo(f"design with accommodation written to {save_design}", err=True)
    return d


def _refuse_nonfinite(m: dict) -> None:
    """A non-finite number is never printed as a result."""
    bad = _nonfinite(m)
    if bad:
        first = bad[:6]  # the first keys (a list, not a message's text)
        raise ParameterError(
            f"the run's results are not finite ({', '.join(first)}{' ...' if len(bad) > 6 else ''}): the closed "
            "loop overflowed with these settings. Lower the noise or the fault sizes, or check "
            "the design"
        )


def _say_simulation(d, plant, res, m: dict, as_json: bool) -> None:
    """The metrics (in words, or the document with ``--json``), the notes, the change of step and the warnings."""
    warn = _warnings(m, list(plant.input_names), list(plant.fault_names), list(plant.output_names),
                     list(plant.output_units), states=list(plant.state_names), state_units=list(plant.state_units))  # fmt: skip
    warn += _why(d, m)
    change = m.get("dt_change")
    if change:  # one step everywhere: a step other than the design's is said, also with --json (on stderr)
        click.echo(
            f"note: simulated at dt = {change['to']:g}, not the design's sample time {change['from']:g} "
            f"({change['why']}); the generated C runs {change['from']:g} unless --sample-time says otherwise",
            err=True,
        )
    if as_json:
        click.echo(json.dumps(m, indent=1))
    else:
        click.echo(_summary(d.plant, m))
        for line in _window_lines(m):
            click.echo(line)
        for note in getattr(res, "notes", ()) or ():
            click.echo(f"  note: {note}")
    for w in warn:
        click.echo(textwrap.fill("fte: " + w, width=100), err=True)


@click.command()
@click.argument("target", metavar="DESIGN.json|PLANT")
@click.option("--vary", "vary", multiple=True, required=True,
              help="NAME=V1,V2,... with NAME one of fault_scale, noise_scale, d_scale, measurement_noise_scale; "
                   "repeat for a grid.")  # fmt: skip
@click.option("--paths", type=int, help="Brownian paths per point (default: the scenario's).")
@_seed_option
@_scheduler_option
@_fast_math_option
@click.option(
    "--out",
    "out_dir",
    type=click.Path(file_okay=False),
    help="Write sweep.json, sweep.csv and sweep.png here.",
)
@click.option("--json", "as_json", is_flag=True, help="Print the list of points (JSON) on stdout.")
@click.option("--quiet", is_flag=True, help="No progress bar.")
@_plant_option
@_allow_option
@_guard
def sweep(
    target, vary, paths, seed, scheduler, fast_math, out_dir, as_json, quiet, plant_opt, allow_uncertified
):
    """Monte Carlo over a grid of fault, noise and unknown-input factors: one metrics document per point."""
    from .._atomic import atomic_write_text
    from .._resources import check_paths_memory
    from ..plants import load_plant, load_scenario
    from ..sim._sweep import parse_vary, to_csv, to_json
    from ..sim._sweep import sweep as run_sweep

    grid = parse_vary(vary)
    _outputs(out_dir)
    _check_paths(paths)
    _check_seed(seed)
    d, spec = _design_or_plant(
        target, progress=not quiet, plant=plant_opt, allow_uncertified=allow_uncertified
    )
    spec = _need_plant(d, spec, "sweep")
    plant = load_plant(spec)
    scenario = load_scenario(spec)
    check_paths_memory(d, scenario, paths or scenario.paths, None, False)
    points = run_sweep(d, plant, scenario, grid, paths=paths or scenario.paths, seed=seed, scheduler=scheduler,
                       progress=not quiet, exact=not fast_math)  # fmt: skip
    if out_dir:
        from ..plot import sweep_figure

        out = Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        atomic_write_text(out / "sweep.json", to_json(points))
        atomic_write_text(out / "sweep.csv", to_csv(points))
        fig = sweep_figure(points, d.plant, out, list(plant.fault_names))
        click.echo(f"sweep.json, sweep.csv and {fig.name} written to {out_dir}", err=True)
    if as_json:
        click.echo(to_json(points))
    else:
        for p in points:
            m = p["metrics"]
            click.echo(", ".join(f"{k} = {v:g}" for k, v in p["point"].items()) + ": fault error (relative RMS, "
                       f"whole windows) {_fmt_list(m['fault_rel_rms_error'])}, false-alarm peak "
                       f"{_fmt_list(m['false_alarm_peak'])}, FTC true ratio {_num(m['ftc_true_ratio'])}")  # fmt: skip
    for p in points:  # the per-window verdicts, as fte simulate gives them, named by their point
        at = ", ".join(f"{k} = {v:g}" for k, v in p["point"].items())
        for w in _warnings(p["metrics"], list(plant.input_names), list(plant.fault_names), list(plant.output_names),
                           list(plant.output_units), states=list(plant.state_names),
                           state_units=list(plant.state_units)):  # fmt: skip
            click.echo(textwrap.fill(f"fte: at {at}: {w}", width=100), err=True)
