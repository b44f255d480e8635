"""`fte reproduce`: the paper's two examples end to end, and a Markdown report a control engineer can check.

For each example: derive the T-S model from the CasADi equations (and compare with the printed
matrices), design both variants and certify them, simulate the conditioned design on the
nonlinear stochastic plant (the paper's path counts), generate the embedded C, compile it
under the strict flags and check it against the Python step over a closed loop, time it.
Stages report through a ``log`` callback; nothing here prints.
"""

from __future__ import annotations

import dataclasses
import json
import platform
import time
from collections.abc import Callable
from importlib import metadata
from pathlib import Path

import numpy as np

from ._atomic import atomic_write_text
from ._text import shorten
from .design import DesignOptions
from .design import design as run_design
from .design.core import LMIS
from .errors import InfeasibleDesignError, SolverFailedError
from .plants import BUILTIN, PRINTED, SCENARIOS
from .sim import protected
from .ts import derive

__all__ = ["reproduce", "versions"]

#: the parameters of the paper's Section 6, which the `paper` variant (the problem as printed) is solved at;
#: the conditioned design uses the plant's design defaults (the three-tank's are `fte tune`'s)
SECTION_6_PARAMS = {
    "manipulator": {"gamma": 2.0, "gamma1": 0.01, "sigma": 0.2, "delta": 1e-5, "epsilon": 1e-5},
    "three-tank": {"gamma": 1.0, "gamma1": 0.9, "sigma": 5.0, "delta": 1e-4, "epsilon": 1e-4},
}

DEPENDENCIES = (
    "fte_casadi",
    "casadi",
    "numpy",
    "scipy",
    "cvxpy",
    "clarabel",
    "scs",
    "matplotlib",
    "click",
    "tqdm",
)


def versions() -> dict[str, str]:
    out = {"python": platform.python_version()}
    for name in DEPENDENCIES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def _mat(M, digits: int = 5) -> str:
    M = np.atleast_2d(np.asarray(M, dtype=float))
    rows = ["  ".join(f"{v: .{digits}g}" for v in row) for row in M]
    return "```\n" + "\n".join(rows) + "\n```"


def _g(v, fmt: str = ".3g") -> str:
    return "n/a" if v is None else format(v, fmt)


def _derive_section(ts, printed: dict | None) -> list[str]:
    out = ["### Derived T-S model", ""]
    out.append(
        f"Method: **{ts.method}**, {ts.r} rules. Premises: "
        + "; ".join(f"`{p.name} = {p.expr}` in [{p.min:.6g}, {p.max:.6g}]" for p in ts.premises)
        + "."
    )
    if printed is None:  # not a plant of the paper: nothing printed to compare with
        return out + [""] + _fidelity_lines(ts)
    out += [
        "",
        "| rule | max abs(A - printed A) | max abs(B - printed B) | max abs(W - printed W) |",
        "|---|---|---|---|",
    ]
    for i, lm in enumerate(ts.local_models):
        dA = np.max(np.abs(lm.A - np.asarray(printed["A"][i])))
        dB = np.max(np.abs(lm.B - np.asarray(printed["B"])))
        dW = np.max(np.abs(lm.W - np.asarray(printed["W"][i]))) if "W" in printed else None
        out.append(f"| {i + 1} | {dA:.2g} | {dB:.2g} | {_g(dW, '.2g')} |")
    out.append("")
    for i, lm in enumerate(ts.local_models):
        out += [f"Rule {i + 1}: derived A_{i + 1}", _mat(lm.A), f"printed A_{i + 1}", _mat(printed["A"][i])]
        if np.any(lm.a):
            out += [
                f"affine offset a_{i + 1} (kept by the observer, see docs/method.md)",
                _mat(lm.a[None, :]),
            ]
    if "W" in printed:
        out.append(
            "The printed W_2[3,2] = 0.005 is a rounding of 0.006 - 0.003 x 0.2172 = 0.00535, which the derivation gives."
        )
    return out + _fidelity_lines(ts)


def _fidelity_lines(ts) -> list[str]:
    f = ts.fidelity
    return [
        "",
        f"Fidelity: largest |T-S - nonlinear| over {f.samples} samples of the region: drift "
        f"{f.drift_max_abs_error:.3g} ({100 * f.drift_max_rel_error:.3g} % of the largest drift), diffusion "
        f"{f.diffusion_max_abs_error:.3g}; along a {f.trajectory_horizon:.4g} s open-loop trajectory: "
        f"{f.trajectory_max_abs_error:.3g}"
        + (f" (stopped early: {f.trajectory_stop})." if f.trajectory_stop else "."),
        "",
    ]


def _design_rows(designs: dict, printed: dict | None) -> list[str]:
    out = [
        "| variant | certified | theta | cond(Pbar) | max abs(L_i1) | max abs(K_j) | max Re eig(R_i) | max Re eig(A_i+B_iK_j) | ts_max | LMI max eig "
        + " / ".join(f"({k})" for k in LMIS)
        + " | time |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for variant, d in designs.items():
        if isinstance(d, str):
            out.append(f"| {variant} | failed | {d} | | | | | | | | |")
            continue
        c = d.checks
        lmi = c["lmi_max_eig"]
        K = max(float(np.max(np.abs(k))) for k in d.K)
        out.append(
            f"| {variant} | {'yes' if d.certified else 'NO'} | {d.theta:.3g} | {c['cond_Pbar']:.3g} | {c['max_abs_L1']:.3g} | "
            f"{K:.3g} | {c['R_max_real_eig']:.3g} | {c['closed_loop_max_real_eig']:.3g} | {c['ts_max']:.3g} | "
            + " / ".join(f"{lmi[k]:.2g}" if k in lmi else "-" for k in LMIS)
            + f" | {d.timings['total_s']:.2f} s |"
        )
    if printed is None:
        return out
    K = np.asarray(printed["K"])
    out.append(
        f"| paper (printed) | - | {printed['theta']:.3g} | - | {printed['max_abs_L1']:.3g} | {np.max(np.abs(K)):.4g} | - | - | - | - | - |"
    )
    return out


def _c_section(d, folder: Path) -> tuple[list[str], dict]:
    from .bench import bench_c_step
    from .codegen import (
        default_sample_time,
        find_compiler,
        generate_c,
        memory_report,
    )
    from .errors import CodegenError, MissingDependencyError
    from .plants import SCENARIOS
    from .sim import check_c

    scenario = SCENARIOS[d.plant]()
    sample_time = default_sample_time(d, scenario.dt)
    files = generate_c(d, folder, sample_time=sample_time)
    out = [f"Generated into `{folder.name}/` ({', '.join(f.name for f in files)}), Ts = {sample_time:g} s."]
    info: dict = {"ts": sample_time}  # the report document's key (kept: documents are not renamed)
    if find_compiler() is None:
        return out + ["No C compiler found: the C was not compiled or checked here."], info
    got = check_c(d, BUILTIN[d.plant](), scenario, folder, sample_time=sample_time)
    if not got.ok:  # the report's C is the loop simulated, or the report says nothing of it
        raise CodegenError(f"{d.plant}: {got.render()}")
    info["max_diff"] = max(got.diff.values())
    info["steps"] = got.samples
    info["check"] = {"ok": got.ok, "refused": got.refused, "diff": got.diff, "scale": got.scale}
    try:  # the timings need the benchmark's C compiled and run; the sizes do not
        b = bench_c_step(d, sample_time=sample_time, iters=100_000, reps=3)
    except (MissingDependencyError, CodegenError) as exc:
        b = {
            "casadi_us": None,
            **memory_report(d, sample_time=sample_time),
            "note": f"timings: not measured ({shorten(exc, 200)})",
        }
    info["bench"] = b
    out += [
        f"Compiled with `cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic` (`fte codegen --check`): {got.render()}.",
        "",
        "| C step | hand-written C loop | ratio | CasADi from Python | state | constants | stack locals |",
        "|---|---|---|---|---|---|---|",
        f"| {_g(b.get('c_ns'), '.1f')} ns | {_g(b.get('hand_ns'), '.1f')} ns | {_g(b.get('ratio'), '.2f')} | "
        f"{_g(b['casadi_us'], '.1f')} us | {b['state_bytes']} B | {b['const_bytes']} B (+{b['sparsity_bytes']} B sparsity) | "
        f"{b['locals_bytes']} B |",
    ]
    if b.get("note"):
        out += ["", f"({b['note']}.)"]
    return out, info


def _iv(iv) -> str:
    return "" if not iv else f" [{iv[0]:.3g}, {iv[1]:.3g}]"


def _windows_section(m: dict, plant) -> list[str]:
    """One row per fault window with the true figures and their 95 % intervals over the paths; the verdicts said
    plainly below."""
    from .verdicts import verdicts

    out = ["Per fault window (FTC run, all paths pooled; docs/interface.md gives each formula; [a, b]: the 95 % "
           "interval over the paths; **bold**: tolerant control worse than none on the true outputs, its interval "
           "above 1; a ratio above 1 whose interval holds 1 is a tie):", "",
           "| fault | window | fault error (whole window) | settled part | settling time | detected (within the allowed "
           "delay) / standing alarms / missed | detection delay "
           f"| FTC true ratio (per output: {', '.join(plant.output_names)}) | after the window, no fault in the plant: "
           "span, FTC true ratio (per output) | compensated ratio | inputs at a limit "
           f"({', '.join(plant.input_names)}) |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]  # fmt: skip

    def worse(v, iv) -> bool:
        return v is not None and v > 1.0 and (iv is None or iv[0] > 1.0)

    def ftc(f: dict) -> str:
        r, riv = f["ftc_true_ratio"], f.get("ftc_true_ratio_interval")
        rs = f"**{r:.3g}{_iv(riv)} (worse than none)**" if worse(r, riv) else f"{_g(r)}{_iv(riv)}"
        ivs = f.get("ftc_true_ratio_per_output_interval") or [None] * len(f["ftc_true_ratio_per_output"])
        per = ", ".join(
            f"**{v:.3g}**" if worse(v, iv) else _g(v) for v, iv in zip(f["ftc_true_ratio_per_output"], ivs)
        )
        return f"{rs} ({per})"

    for w in m["windows"]:
        a = w.get("after_window")
        after = "-" if not a else f"[{a['start']:g}, {a['stop']:g}): {ftc(a)}"
        det = "-" if w.get("missed_detections") is None else (
            f"{_g(w['detection_probability'])}{_iv(w.get('detection_probability_interval'))} "
            f"({_g(w.get('detection_probability_within'))} within {_g(w.get('detection_delay_allowed'))}) / "
            f"{w['standing_alarm_paths']} / {w['missed_detections']}")  # fmt: skip
        sat = ", ".join(_g(v) for v in w["input_saturation"])
        out.append(
            f"| {w['fault']} | [{w['start']:g}, {w['stop']:g}) | {_g(w['fault_rel_rms_error'])}"
            f"{_iv(w.get('fault_rel_rms_error_interval'))} | {_g(w['fault_rel_rms_error_settled'])} | "
            f"{_g(w['settling_time'])} | {det} | {_g(w['detection_delay'])} | {ftc(w)} | {after} | "
            f"{_g(w['ftc_compensated_ratio'])} | {sat} |"
        )
    names = plant.fault_names
    out += ["", "Each fault's estimate outside its own windows, relative to the fault: peak after the start-up "
            f"allowance {m['transient']:.3g} and not within {m['settle_after']:.3g} after a window's end "
            + ", ".join(f"{nm} {_g(v)}" for nm, v in zip(names, m["false_alarm_peak"]))
            + "; without the allowances " + ", ".join(f"{nm} {_g(v)}" for nm, v in zip(names, m["false_alarm_peak_raw"]))
            + " (in the start-up " + ", ".join(f"{nm} {_g(v)}" for nm, v in zip(names, m["false_alarm_peak_startup"]))
            + "; after a window " + ", ".join(f"{nm} {_g(v)}" for nm, v in zip(names, m["false_alarm_peak_after_window"]))
            + "); RMS " + ", ".join(f"{nm} {_g(v)}" for nm, v in zip(names, m["false_alarm_rel_rms"])) + "."]  # fmt: skip
    out += ["", "| detection of | threshold (from t) | start-up blocks | calibration | promised false alarms per unit "
            "time (asked) | measured, fault-free paths | measured, faulty run outside its windows |",
            "|---|---|---|---|---|---|---|"]  # fmt: skip
    for e in m.get("detection") or []:
        out.append(
            f"| {e['fault']} | {_g(e['threshold'])} ({_g(e.get('steady_from'), '.4g')}) | "
            f"{len(e.get('startup_thresholds') or [])} | {e['calibration_paths']} paths, "
            f"{_g(e.get('calibration_hours'))} path-hours, {e.get('calibration_method')} |"
            f"{_iv(e.get('false_alarm_rate_interval'))} ({_g(e['false_alarm_rate_asked'])}) | "
            f"{_g(e['false_alarm_rate'])}{_iv(e.get('false_alarm_rate_measured_interval'))} | "
            f"{_g(e.get('false_alarm_rate_ftc_run'))}{_iv(e.get('false_alarm_rate_ftc_run_interval'))} |"
        )
    out += ["", f"Rule: {(m.get('detection') or [{}])[0].get('rule', 'no detection')}."]
    vs = verdicts(m, list(plant.input_names), list(plant.fault_names), list(plant.output_names),
                  list(plant.output_units), states=list(plant.state_names), state_units=list(plant.state_units))  # fmt: skip
    if vs:
        out += ["", "Verdicts:", ""] + [f"- **{v['verdict']}**: {v['text']}" for v in vs]
    return out + [""]


#: paths per point of the detection-probability curves in the report, the calibration paths of the noise level the
#: run did not calibrate for (its thresholds serve the figure, not a promise), and the measurement noise added where
#: the scenario has none: this multiple of each output's spread over the fault-free paths (its standard deviation
#: across the paths at each sample, RMS over the samples after the start-up allowance: a sensor as noisy as the
#: plant's own random fluctuation)
DETECT_PATHS = 32
OTHER_CALIBRATION_PATHS = 200
REPORT_NOISE = 1.0


def _detectability_sets(d, plant, sc, res, cal, seed: int):
    """The detection probability against each fault's size without measurement noise and with it (the scenario's,
    or REPORT_NOISE x each output's spread over the fault-free paths), each with its own thresholds: the run's
    calibration ``cal`` for the scenario's own noise level, OTHER_CALIBRATION_PATHS paths for the other."""
    from .sim import detectability

    kw = dict(paths=DETECT_PATHS, seed=seed)
    other = dict(kw, calibration_paths=OTHER_CALIBRATION_PATHS)
    if sc.measurement_noise is None:
        after = res.free.y[:, res.t >= res.metrics["transient"]]
        # the spread over the paths at each sample, RMS over the samples: the random part, not the start-up's course
        spread = np.sqrt(np.mean(after.std(axis=0) ** 2, axis=0)) if after.size else np.ones(plant.p)
        noise = tuple(float(v) for v in REPORT_NOISE * spread)
        noisy = dataclasses.replace(sc, measurement_noise=noise)
        sets = [detectability(d, plant, sc, calibration=cal, **kw), detectability(d, plant, noisy, **other)]
    else:
        noise = tuple(sc.measurement_noise.reported(1.0))
        sets = [detectability(d, plant, sc, scales={"measurement_noise_scale": 0.0}, **other),
                detectability(d, plant, sc, calibration=cal, **kw)]  # fmt: skip
    sets[0]["label"], sets[1]["label"] = "without measurement noise", "with measurement noise"
    return sets, noise


def _detectability_section(sets, noise, plant) -> list[str]:
    """The smallest fault detected on 95 % of the paths within the allowed delay, without and with noise."""
    out = [
        f"The smallest fault the design detects: each fault alone, at sizes found in steps of 4 then halved twice, "
        f"{sets[0]['paths']} paths a point; detected = the alarm rose within the allowed delay of the onset (three "
        "observer time constants, at most the window) on a path where it was off. With measurement noise (the scenario's, "
        "or as large as each output's spread over the fault-free paths after the start-up): std "
        + ", ".join(f"{nm} {v:.3g}" for nm, v in zip(plant.output_names, noise))
        + f" (each noise level with its own thresholds; the one the run was not calibrated for on "
        f"{OTHER_CALIBRATION_PATHS} paths).",
        "",
        "| fault | within | without noise | with noise |",
        "|---|---|---|---|",
    ]
    for c0, c1 in zip(sets[0]["curves"], sets[1]["curves"]):
        out.append(f"| {c0['fault']} | {_g(c0['delay'])} | {_mdf(c0)} | {_mdf(c1)} |")
    return out + [""]


def _mdf(c: dict) -> str:
    v = c["min_detectable_fault"]
    return f"{v:.3g} (x {c['min_detectable_factor']:.3g})" if v is not None else f"n/a ({c['why']})"


def _saturation_section(m: dict, m_free: dict, d, plant) -> list[str]:
    """What the actuator limits do: the same paths and noise with and without them."""
    lim = ", ".join(f"{nm} in [{lo:g}, {hi:g}]" for nm, (lo, hi) in zip(plant.input_names, d.input_limits))
    return [
        f"Actuator limits ({lim}): the same run without them, for comparison (same seed, same paths):",
        "",
        "| | with limits | without |",
        "|---|---|---|",
        f"| fault error (relative RMS, whole windows) | {', '.join(_g(v) for v in m['fault_rel_rms_error'])} | "
        f"{', '.join(_g(v) for v in m_free['fault_rel_rms_error'])} |",
        f"| FTC true ratio | {_g(m['ftc_true_ratio'])} | {_g(m_free['ftc_true_ratio'])} |",
        f"| state RMS error | {', '.join(_g(v) for v in m['state_rms_error'])} | "
        f"{', '.join(_g(v) for v in m_free['state_rms_error'])} |",
        f"| inputs at a limit | {', '.join(_g(v) for v in m['input_saturation'])} | (no limits) |",
        "",
        _saturation_sentence(m, m_free),
        "",
    ]


def _rel(a, b) -> float:
    return abs(a - b) / abs(b) if a is not None and b not in (None, 0) else 0.0


def _saturation_sentence(m: dict, m_free: dict) -> str:
    """What the limits did, in words, from the numbers."""
    d_fault = max(
        (_rel(a, b) for a, b in zip(m["fault_rel_rms_error"], m_free["fault_rel_rms_error"])), default=0.0
    )
    d_ratio = _rel(m["ftc_true_ratio"], m_free["ftc_true_ratio"])
    in_windows = max((v for w in m["windows"] for v in w["input_saturation"]), default=0.0)
    where = ("no input reaches a limit inside a fault window (only in the start-up transient)" if in_windows == 0
             else f"inputs sit at a limit for up to {100 * in_windows:.1f} % of a fault window")  # fmt: skip
    return (f"Saturation changes the fault estimation error by {100 * d_fault:.2g} % and the FTC true ratio by "
            f"{100 * d_ratio:.2g} % (relative): {where}.")  # fmt: skip


def _reproduce_one(name: str, out: Path, seed: int, log, paths: int | None) -> tuple[list[str], dict]:
    """The report's section of one plant (derive, design, Monte Carlo, detectability, C) and its summary."""
    printed = PRINTED.get(name)  # None for a plant that is not the paper's (the quadruple tank)
    plant = BUILTIN[name]()
    t0 = time.perf_counter()
    log(f"[{name}] derive T-S model")
    ts = derive(plant)
    sec = [f"## {name}", ""] + _derive_section(ts, printed)
    designs = _designs(name, ts, plant, seed, log, printed is not None)
    d = designs["conditioned"]
    if isinstance(d, str):
        raise InfeasibleDesignError(f"{name}: the conditioned design failed: {d}")
    d.save(out / f"{name}-design.json")
    if not isinstance(designs.get("paper", ""), str):
        designs["paper"].save(out / f"{name}-design-paper.json")
    sec += _design_lines(d, designs, printed)
    msec, m, figs = _monte_carlo_section(name, d, plant, out, seed, paths, log, printed is not None)
    sec += msec
    log(f"[{name}] generate, compile and check the embedded C")
    cdir = out / "c" / name.replace("-", "_")
    csec, cinfo = _c_section(d, cdir)
    sec += ["### Embedded C", ""] + csec + [""]
    summary = {
        "metrics": m,
        "figures": [str(f) for f in figs],
        "c": {k: v for k, v in cinfo.items() if k != "bench"},
        "c_bench": cinfo.get("bench"),
        "seconds": time.perf_counter() - t0,
        "designs": {k: (v if isinstance(v, str) else v.checks) for k, v in designs.items()},
    }
    return sec, summary


def _designs(name: str, ts, plant, seed: int, log, paper: bool) -> dict:
    """The conditioned design (protected, as fte design writes it) and, for the paper's plants, the paper's
    variant at Section 6's parameters; a variant that fails is its message."""
    designs: dict = {}
    for variant in ("conditioned", "paper") if paper else ("conditioned",):
        log(f"[{name}] design, variant {variant}")
        try:
            given = SECTION_6_PARAMS.get(name, {}) if variant == "paper" else {}
            sc = SCENARIOS[name]()
            options = sc.design_options(DesignOptions(variant=variant, plant_spec=name, **given))
            designs[variant] = run_design(ts, options)
            if variant == "conditioned":  # as fte design writes it (the paper's variant compensates always)
                designs[variant] = protected(designs[variant], plant, sc, paths=sc.paths, seed=seed)
        except (InfeasibleDesignError, SolverFailedError) as exc:
            designs[variant] = " ".join(str(exc).split())
            log(f"[{name}]   variant {variant} failed: {shorten(designs[variant], 160)}")
    return designs


def _design_lines(d, designs: dict, printed) -> list[str]:
    """H (against the printed one), the designs' table, the gains and the design's notes."""
    sec = ["### Unknown-input gain H (17)", "", _mat(d.H, 7)]
    if printed is not None:
        sec.append(
            f"largest difference to the printed H: {float(np.max(np.abs(d.H - np.asarray(printed['H'])))):.2g}"
        )
    sec.append("")
    sec += ["### Designs", ""] + _design_rows(designs, printed) + [""]
    sec += [
        f"Conditioned gains K_j (u = u_ref + sum_j h_j (K_j xhat + Kf fhat), u_ref = {np.round(d.u_ref, 6).tolist()}):",
        "",
    ]
    if all(np.array_equal(K, d.K[0]) for K in d.K):
        sec += [f"K_j = K for every rule j = 1..{len(d.K)}", _mat(d.K[0])]
    else:
        for j, K in enumerate(d.K):
            sec += [f"K_{j + 1}", _mat(K)]
    sec += ["Kf", _mat(d.Kf), ""]
    notes = [s for s in d.status]
    if not isinstance(designs.get("paper", ""), str):
        notes += [f"paper variant: {s}" for s in designs["paper"].status]
    if notes:
        sec += ["Notes from the design:", ""] + [f"- {s}" for s in notes] + [""]
    return sec


def _monte_carlo_section(name: str, d, plant, out: Path, seed: int, paths: int | None, log,
                         paper: bool) -> tuple[list[str], dict, list]:  # fmt: skip
    """The Monte Carlo of the conditioned design (thresholds calibrated first), its detectability and, with input
    limits, the run without them: the lines, the metrics and the figures."""
    from .plot import detectability_figure, write_figures
    from .sim import attach, calibrate_detection, save_result, simulate
    from .sim import metrics as sim_metrics

    sc = SCENARIOS[name]()
    npaths = max(paths or 0, sc.paths)
    log(f"[{name}] calibrate the detection thresholds on fault-free paths")
    cal = calibrate_detection(d, plant, sc, paths=npaths, seed=seed)
    log(f"[{name}] simulate {npaths} paths x 3 runs on the nonlinear plant")
    res = simulate(d, plant, sc, paths=npaths, seed=seed, progress=False, calibration=cal)
    m = sim_metrics(res)
    log(
        f"[{name}] the smallest fault detected, without and with measurement noise ({DETECT_PATHS} paths a point)"
    )
    sets, noise = _detectability_sets(d, plant, sc, res, cal, seed)
    m = attach(m, sets)
    save_result(res, out / f"{name}-simulation.npz")
    sub = "figures" if paper else f"figures/{name}"  # the paper's figure numbers, or a folder
    figs = write_figures(res, out / sub)
    sec = _metrics_table(m, plant) + _windows_section(m, plant)
    fig = detectability_figure(sets, name, out / sub, name=f"{name.replace('-', '_')}_detectability.png")
    sec += _detectability_section(sets, noise, plant) + [f"![detectability]({sub}/{fig.name})", ""]
    figs = [*figs, fig]
    if d.input_limits is not None:
        log(f"[{name}] simulate again without input limits, to say what saturation does")
        free = simulate(dataclasses.replace(d, input_limits=None), plant, sc, paths=npaths, seed=seed,
                        progress=False, detect=False)  # fmt: skip
        sec += _saturation_section(m, free.metrics, d, plant)
    for f in figs:
        sec.append(f"![{f.stem}]({sub}/{f.name})")
    sec.append("")
    return sec, m, figs


def _metrics_table(m: dict, plant) -> list[str]:
    """The Monte Carlo's headline metrics as a table."""
    return [
        "### Monte Carlo (conditioned design, nonlinear plant)",
        "",
        f"{m['paths']} paths, T = {m['T']:g} s, dt = {m['dt']:g} s, seed {m['seed']}, {m['wall_s']:.2f} s wall.",
        "",
        "| metric | value |",
        "|---|---|",
        f"| state RMS error x - xhat (t >= {m['transient']:.3g}, FTC run) | {', '.join(_g(v) for v in m['state_rms_error'])} |",
        f"| fault error, relative RMS over whole windows ({', '.join(plant.fault_names)}) | {', '.join(_g(v) for v in m['fault_rel_rms_error'])} |",
        f"| FTC true ratio (C x_FTC vs C x_noFTC, against fault-free) | {_g(m['ftc_true_ratio'])} |",
        f"| compensated ratio (yc_FTC vs y_noFTC, the paper's Figs 8-10: estimation) | {_g(m['ftc_compensated_ratio'])} |",
        f"| samples outside the plant's region | {_g(m['outside_region'])} |",
        f"| measurements the generated C would refuse (fraction of samples; of paths) | "
        f"{_g(m.get('outside_c_range'))}; {_g(m.get('outside_c_range_paths'))} |",
        f"| inputs at a limit ({', '.join(plant.input_names)}; fraction of samples, FTC run) | "
        f"{', '.join(_g(v) for v in m['input_saturation'])} |",
        "",
    ]


def reproduce(
    which: str = "all",
    out: str | Path = "fte-report",
    *,
    seed: int = 0,
    paths: int | None = None,
    log: Callable[[str], None] = lambda s: None,
) -> Path:
    """Run the paper's examples end to end; write ``out/report.md`` and return its path."""
    names = list(BUILTIN) if which == "all" else [which]
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    body, summary = [], {}
    for name in names:
        sec, s = _reproduce_one(name, out, seed, log, paths)
        body += sec
        summary[name] = s
    total = time.perf_counter() - t0
    head = [
        "# fte_casadi: the paper's examples, reproduced",
        "",
        f"Command: `fte reproduce {which} --out {out}`; seed {seed}; {total:.1f} s on this machine "
        f"({platform.machine()}, {platform.system()}, Python {platform.python_version()}).",
        "",
        "Every LMI eigenvalue below is recomputed with numpy at the solver's returned point (negative = the LMI "
        "holds); `certified` means every one of them holds together with the stability checks. `conditioned` is "
        "the design fte_casadi uses; `paper` is the problem as printed (with the corrections of docs/method.md), reported "
        "with its true numbers.",
        "",
    ]
    tail = ["## Versions", "", "| package | version |", "|---|---|"]
    tail += [f"| {k} | {v} |" for k, v in versions().items()]
    tail += ["", f"Seed: {seed}. Regenerate with the command above.", ""]
    atomic_write_text(out / "report.md", "\n".join(head + body + tail))
    atomic_write_text(out / "summary.json", json.dumps(summary, indent=1, default=_json_default))
    return out / "report.md"


def _json_default(o):
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, (np.floating, np.integer)):
        return o.item()
    return str(o)
