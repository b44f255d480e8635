"""The verdicts on a metrics document (docs/interface.md), in one place.

``fte simulate`` warns by them, the report marks by them, ``fte tune`` chooses by them and
:func:`fte_casadi.design._limits.explain_metrics` explains the windows and faults they single out.
A module of its own (as :mod:`fte_casadi._rounding`), so that every step of the package can read them
without importing the simulator. Every verdict is judged on the figures measured on the true plant.
"""

from __future__ import annotations

from ._rounding import ratio_text as ratio

__all__ = [
    "WORSE_THAN_NONE",
    "FALSE_ALARM",
    "SATURATED",
    "OUTSIDE_REGION",
    "POOR_ESTIMATE",
    "SLOW_OBSERVER",
    "SATURATES_EARLY",
    "SENSOR_MOTION",
    "verdicts",
    "judged_ftc_ratio",
    "judged_ftc_ratios_per_output",
    "window_label",
]

#: a window's ``ftc_true_ratio`` above this: tolerant control leaves the TRUE outputs worse than none
WORSE_THAN_NONE = 1.0
#: a fault estimate's peak outside its windows (``false_alarm_peak``) at or above this fraction of the
#: fault's peak: false alarms (an alarm set between the two cannot tell them from the fault)
FALSE_ALARM = 0.5
#: an input at a limit for more than this fraction of a window: the tolerance is that of a saturated actuator
SATURATED = 0.05
#: more than this fraction of the samples outside the plant's region: the T-S model is not exact there
OUTSIDE_REGION = 0.01
#: a window's fault error (relative RMS over the whole window) at or above this: the estimate misses half the fault
POOR_ESTIMATE = 0.5
#: the observer's slowest time constant times this longer than a fault window: it cannot settle inside it
SLOW_OBSERVER = 3.0
#: the design's loop keeps its inputs within their limits only on a set reaching less than this fraction of the
#: plant's region (``checks.loop.unsaturated.fraction``): the controller saturates for small deviations
SATURATES_EARLY = 0.01
#: a sensor fault's window where a TRUE output moves from the fault-free run by more than this times the fault's
#: peak as that output reads it (RMS over the window, tolerant control on): the loop turns the sensor's error into
#: a larger motion of the plant
SENSOR_MOTION = 1.0


def window_label(w: dict) -> str:
    """A window of the metrics document in words: ``the window of fs [7, 10)``."""
    return f"the window of {w['fault']} [{w['start']:g}, {w['stop']:g})"


def _crosstalk(w: dict, faults) -> str:
    """The other faults' estimates in a window, relative to their own peaks: what Kf feeds into the plant there."""
    xs = [(faults[q] if q < len(faults) else str(q), v) for q, v in enumerate(w.get("crosstalk_peak") or [])
          if v is not None and v > 0.05]  # fmt: skip
    if not xs:
        return ""
    txt = ", ".join(f"{nm} {v:.3g}" for nm, v in xs)
    return (
        f"; the estimates of the other faults show cross-talk there (peak relative to their own faults: {txt}), "
        "which the tolerant control term Kf fhat feeds into the plant"
    )


def applied_nothing(w: dict) -> bool:
    """Tolerant control added nothing to u in window ``w``: its compensation is zero at every sample (per input,
    ``ftc_compensation_rms``); the window's FTC ratios then differ from 1 only by what the runs carried in."""
    comp = w.get("ftc_compensation_rms")
    return bool(comp) and all(v is not None and v == 0 for v in comp)


def _cause(w: dict, faults, output: int | None = None) -> str:
    """What made tolerant control differ from none in window ``w``: where it applied nothing there (its
    compensation is zero at every sample, ``ftc_compensation_rms``), what the runs carried into the window
    (``onset_deviation``); else the other faults' cross-talk that it fed into the plant (:func:`_crosstalk`)."""
    on = w.get("onset_deviation") or {}
    if applied_nothing(w):
        a, b = on.get("ftc"), on.get("no_ftc")
        entered = ("" if a is None or b is None else
                   f", the runs entering it at a deviation from the fault-free run of {a:.3g} with tolerant control "
                   f"and {b:.3g} without (onset_deviation)")  # fmt: skip
        return (
            "; tolerant control applied nothing in this window (the compensation it adds to u is zero at every "
            f"sample, ftc_compensation_rms): the difference was carried into it from before{entered}"
            + _carry_free(w, output)
        )
    return _crosstalk(w, faults)


def _carry_free(w: dict, output: int | None = None) -> str:
    """What the window measures with nothing carried in (``carry_free_ratio``, :mod:`fte_casadi.sim._carry`), on
    the whole or on ``output``."""
    if output is None:
        r = w.get("carry_free_ratio")
    else:
        per = w.get("carry_free_ratio_per_output") or []
        r = per[output] if output < len(per) else None
    if r is None:
        return ""
    key = "carry_free_ratio" if output is None else "carry_free_ratio_per_output"
    on = "" if output is None else " on this output"
    head = (f"; with this fault alone, nothing carried in, tolerant control would measure {ratio(r, 4)}{on} against "
            f"this run without it ({key})")  # fmt: skip
    if r > WORSE_THAN_NONE:
        return head + (": the run without tolerant control gains from the tail it carries in, and no compensation "
                       "that removes the earlier faults' effects does better than none in this window")  # fmt: skip
    return head + ": what makes it worse is tolerant control's own tail from the earlier windows"


def _above(value, interval, level: float) -> bool:
    """``value`` is above ``level`` and, where the document gives its interval over the paths, so is the whole
    interval (otherwise the figure ties with ``level``)."""
    if value is None or not value > level:
        return False
    return interval is None or (interval[0] is not None and interval[0] > level)


def judged_ftc_ratio(w: dict) -> float | None:
    """Window ``w``'s ``ftc_true_ratio`` as the verdicts judge it: :data:`WORSE_THAN_NONE` itself (a tie) where
    the ratio's interval over the paths holds it, else the ratio (None where the window has none). Above
    :data:`WORSE_THAN_NONE` it is "worse than none", as ``fte simulate`` warns; below it, measurably better."""
    return _judged(w.get("ftc_true_ratio"), w.get("ftc_true_ratio_interval"))


def judged_ftc_ratios_per_output(w: dict) -> list[float | None]:
    """Window ``w``'s ``ftc_true_ratio_per_output``, each judged as :func:`judged_ftc_ratio` judges the window's
    (by its own interval, ``ftc_true_ratio_per_output_interval``): above :data:`WORSE_THAN_NONE`, that output is
    worse than none, as ``fte simulate`` warns."""
    ivs = w.get("ftc_true_ratio_per_output_interval") or []
    return [
        _judged(r, ivs[k] if k < len(ivs) else None)
        for k, r in enumerate(w.get("ftc_true_ratio_per_output") or [])
    ]


def _judged(r, iv) -> float | None:
    if r is None:
        return None
    if iv is not None and iv[0] is not None and iv[1] is not None and iv[0] <= WORSE_THAN_NONE <= iv[1]:
        return WORSE_THAN_NONE
    return float(r)


def _iv(interval) -> str:
    """An FTC ratio's interval, its ends told from 1 (:func:`fte_casadi._rounding.ratio_text`)."""
    if interval is None:
        return ""
    return f", 95 % interval {ratio(interval[0], 4)}-{ratio(interval[1], 4)} over the paths"


def _rate_verdicts(m: dict, add) -> None:
    """Too many false alarms: a measured rate whose interval lies above the interval the calibration promised
    (or above the rate asked, without one), on the fault-free paths and in the faulty run outside the fault's
    windows (allowances left out)."""
    for e in m.get("detection") or []:
        asked = e.get("false_alarm_rate_asked")
        promised = e.get("false_alarm_rate_interval") or ([asked, asked] if asked is not None else None)
        if promised is None:
            continue
        for key, run in (("false_alarm_rate", "on fault-free paths"),
                         ("false_alarm_rate_ftc_run", "in the faulty run outside its fault windows")):  # fmt: skip
            v, iv = e.get(key), e.get(f"{key}_interval" if key != "false_alarm_rate" else
                                      "false_alarm_rate_measured_interval")  # fmt: skip
            if v is None:
                continue
            lo = iv[0] if iv is not None else v
            if lo > promised[1]:
                add("false-alarm rate", e["fault"], v,
                    f"the alarm of {e['fault']} is raised {v:.3g} times per unit time {run} (95 % interval "
                    f"{lo:.3g}-{(iv or [v, v])[1]:.3g}), above the {promised[0]:.3g}-{promised[1]:.3g} the thresholds "
                    f"promise at the rate asked ({asked:.3g})")  # fmt: skip


def verdicts(m: dict, inputs=(), faults=(), outputs=(), units=(), states=(), state_units=()) -> list[dict]:
    """The verdicts on metrics document ``m``: a list of ``{"verdict", "where", "value", "text"}`` with
    ``verdict`` one of ``worse than none``, ``worse than none on an output``, ``worse than none after a window``
    (over the span from a window's end to the next window or the horizon, ``after_window``), ``worse than none
    after a window on an output``, ``false alarm``,
    ``false-alarm rate``, ``standing alarm``, ``saturated``, ``poor estimate``, ``slow observer``, ``not
    settled``, ``missed``, ``sensor fault moves the plant``, ``outside region``, ``C stops``. A ratio is worse than none only when its interval over the
    paths lies above 1 (where the document gives one); a ratio above 1 whose interval holds 1 is a tie. A poor
    estimate likewise needs its interval at or above :data:`POOR_ESTIMATE`."""
    out = []

    def add(verdict, where, value, text):
        out.append({"verdict": verdict, "where": where, "value": value, "text": text})

    for name, v in zip(faults, m.get("false_alarm_peak") or ()):
        if v is not None and v >= FALSE_ALARM:
            add("false alarm", name, v,
                f"the estimate of {name} outside its fault windows peaks at {v:.3g} x the fault's own peak "
                f"(>= {FALSE_ALARM:g}): false alarms, e.g. cross-talk from another fault")  # fmt: skip
    _rate_verdicts(m, add)
    for w in m.get("windows", []):
        _tolerance_verdicts(w, add, faults, outputs, units)
        _after_window_verdicts(w, add, faults, outputs)
        _window_verdicts(m, w, add, inputs)
        _sensor_motion_verdict(w, m.get("windows", []), add, outputs, units)
    frac = m.get("outside_region")
    if frac is not None and frac > OUTSIDE_REGION:
        add("outside region", "run", frac,
            f"{100 * frac:.1f} % of the samples leave the plant's region, where the T-S model (and the design's "
            f"certificate) is not exact{_how_far(m, states, state_units)}")  # fmt: skip
    _c_range_verdict(m, add, outputs)
    return out


def _how_far(m: dict, states, units) -> str:
    """Where the runs took the states that left the region (``state_range`` against ``region``), in words; "" where
    the document has neither."""
    got, reg = m.get("state_range"), m.get("region")
    if not got or not reg:
        return ""
    out = []
    for i, (a, b) in enumerate(zip(got["lo"], got["hi"])):
        lo, hi = reg["lo"][i], reg["hi"][i]
        if (lo is not None and a < lo) or (hi is not None and b > hi):
            name = states[i] if i < len(states) else f"state {i}"
            unit = f" {units[i]}" if i < len(units) and units[i] else ""
            side = f"{'-inf' if lo is None else f'{lo:.4g}'} to {'inf' if hi is None else f'{hi:.4g}'}"
            out.append(f"{name} {_apart(a, lo)} to {_apart(b, hi)}{unit} (region {side})")
    return f": the runs take {', '.join(out)}" if out else ""


def _apart(v: float, bound) -> str:
    """``v`` to 4 significant digits, more where that would print it as its region's ``bound``."""
    for digits in (4, 8, 17):
        text = f"{v:.{digits}g}"
        if bound is None or v == bound or text != f"{bound:.{digits}g}":
            return text
    return text


def _c_range_verdict(m: dict, add, outputs) -> None:
    """The generated C would stop: a measurement of the FTC run leaves the range it accepts (on any path)."""
    share = m.get("outside_c_range_paths")
    if not share:
        return
    rng = m.get("c_accepted_range") or {}
    lo, hi = rng.get("lo") or [], rng.get("hi") or []
    per = m.get("outside_c_range_per_output") or []
    which = ", ".join(
        f"{outputs[k] if k < len(outputs) else f'output {k}'} outside [{lo[k]:.4g}, {hi[k]:.4g}] on "
        f"{100 * v:.2g} % of the samples"
        for k, v in enumerate(per)
        if v and k < len(lo) and k < len(hi)
    )
    first = m.get("outside_c_range_first")
    when = f", first at t = {first:.6g}" if first is not None else ""
    add("C stops", "run", share,
        f"on {100 * share:.3g} % of the paths a measurement leaves the range the generated C accepts ({which}"
        f"{when}): there `fte codegen`'s step returns 3 and changes nothing, while this simulation's step runs on, "
        "so the C would not do what this run shows. The range is C x over the plant's region, widened on each side "
        "by 10 % of its width (100 % on an output with a sensor fault; less where the step is not finite): keep the plant in its region, or widen the region (b.region) "
        "to where it runs and design again, then simulate again: a design for a wider region is another loop, and "
        "may run wider still")  # fmt: skip


def _tolerance_verdicts(w: dict, add, faults, outputs, units) -> None:
    """Window ``w``'s tolerant control worse than none: on the true outputs as a whole, else on one of them."""
    where = window_label(w)
    r = w.get("ftc_true_ratio")
    if _above(r, w.get("ftc_true_ratio_interval"), WORSE_THAN_NONE):
        per = w.get("ftc_true_ratio_per_output") or []
        worst = ", ".join(
            f"{outputs[k] if k < len(outputs) else k}: {ratio(v, 4)}"
            for k, v in enumerate(per)
            if v is not None
        )
        add("worse than none", where, r,
            f"in {where} tolerant control makes the TRUE outputs worse than none (ftc_true_ratio {ratio(r, 4)} > "
            f"{WORSE_THAN_NONE:g}{_iv(w.get('ftc_true_ratio_interval'))}; per output {worst})"
            f"{_cause(w, faults)}")  # fmt: skip
    elif r is not None:
        rms = w.get("ftc_true_rms_per_output") or {}
        ivs = w.get("ftc_true_ratio_per_output_interval") or []
        for k, v in enumerate(w.get("ftc_true_ratio_per_output") or []):
            if _above(v, ivs[k] if k < len(ivs) else None, WORSE_THAN_NONE):
                name = outputs[k] if k < len(outputs) else f"output {k}"
                size = ""
                if rms.get("ftc") and rms.get("no_ftc"):
                    unit = f" {units[k]}" if k < len(units) and units[k] else ""
                    size = (f": RMS deviation from the fault-free run {rms['ftc'][k]:.3g}{unit} with it against "
                            f"{rms['no_ftc'][k]:.3g}{unit} without")  # fmt: skip
                add("worse than none on an output", f"{where}, {name}", v,
                    f"in {where} tolerant control makes the true output {name} worse than none (ratio {ratio(v, 4)} > "
                    f"{WORSE_THAN_NONE:g}{_iv(ivs[k] if k < len(ivs) else None)}{size}), though the outputs as a "
                    f"whole are not worse (ftc_true_ratio {ratio(r)}){_cause(w, faults, k)}")  # fmt: skip


def _after_window_verdicts(w: dict, add, faults, outputs) -> None:
    """Tolerant control worse than none after window ``w`` (``after_window``: from its end to the next fault
    window or the horizon, no fault in the plant), on the true outputs as a whole, else on one of them."""
    a = w.get("after_window")
    if not a:
        return
    where = f"the span after {window_label(w)}, [{a['start']:g}, {a['stop']:g})"
    r, ivs = a.get("ftc_true_ratio"), a.get("ftc_true_ratio_per_output_interval") or []
    per = a.get("ftc_true_ratio_per_output") or []
    names = [outputs[k] if k < len(outputs) else f"output {k}" for k in range(len(per))]
    if _above(r, a.get("ftc_true_ratio_interval"), WORSE_THAN_NONE):
        each = ", ".join(f"{names[k]}: {ratio(v, 4)}" for k, v in enumerate(per) if v is not None)
        add("worse than none after a window", where, r,
            f"in {where}, where no fault is in the plant, tolerant control makes the TRUE outputs worse than none "
            f"(ratio {ratio(r, 4)} > {WORSE_THAN_NONE:g}{_iv(a.get('ftc_true_ratio_interval'))}; per output "
            f"{each}){_after_cause(w, a, faults)}{_net(a)}")  # fmt: skip
        return
    for k, v in enumerate(per):
        if r is not None and _above(v, ivs[k] if k < len(ivs) else None, WORSE_THAN_NONE):
            add("worse than none after a window on an output", f"{where}, {names[k]}", v,
                f"in {where}, where no fault is in the plant, tolerant control makes the true output {names[k]} "
                f"worse than none (ratio {ratio(v, 4)} > {WORSE_THAN_NONE:g}{_iv(ivs[k] if k < len(ivs) else None)}), "
                f"though the outputs as a whole are not worse (ratio {ratio(r)}){_after_cause(w, a, faults)}")  # fmt: skip


def _net(a: dict) -> str:
    """Tolerant control over the window and the span after it together (``ftc_true_ratio_with_window``)."""
    r = a.get("ftc_true_ratio_with_window")
    if r is None:
        return ""
    net = "better than none" if r < WORSE_THAN_NONE else "no better than none"
    return (
        f"; over the window and this span together it is {net} (ftc_true_ratio_with_window {ratio(r, 4)}"
        f"{_iv(a.get('ftc_true_ratio_with_window_interval'))})"
    )


def _after_cause(w: dict, a: dict, faults) -> str:
    """Why tolerant control differs from none after window ``w`` (its ``after_window`` figures ``a``): what it
    still adds to u there, and how long the window's fault estimate takes to fall back (``release_time``)."""
    comp = a.get("ftc_compensation_rms")
    if not comp:  # not recorded (a result saved before it was): no cause said
        return ""
    if all(v == 0 for v in comp):
        return ("; tolerant control applied nothing there (its compensation is zero at every sample): the runs left "
                "the window at different states")  # fmt: skip
    rel = w.get("release_time")
    lag = (f"{w['fault']}'s estimate falls back within 10 % of the fault's size {rel:.3g} after its end" if rel is not None
           else f"{w['fault']}'s estimate does not fall back within 10 % of the fault's size before the span ends")  # fmt: skip
    held = ", ".join(f"{v:.3g}" for v in comp)
    return (f"; tolerant control still adds to u there (RMS {held} per input), compensating estimates that lag "
            f"the fault's end ({lag}) or show another fault's cross-talk, while the run without it only recovers "
            "from the deviation the fault left")  # fmt: skip


def _sensor_motion_verdict(w: dict, windows: list, add, outputs, units) -> None:
    """A sensor fault's window where a TRUE output moves from the fault-free run (RMS over the window, the run with
    tolerant control) by more than :data:`SENSOR_MOTION` times the fault's peak as that output reads it
    (``sensor_fault_peak_per_output``): the fault enters only the measurement, so the plant moves only because u follows
    the observer's estimate, which the fault throws off. Not judged where another fault's window overlaps it (the
    motion is then the other fault's too)."""
    size, rms = w.get("sensor_fault_peak_per_output"), w.get("ftc_true_rms_per_output") or {}
    ftc, none = rms.get("ftc") or [], rms.get("no_ftc") or []
    a, b = float(w["start"]), float(w["stop"])
    overlapped = any(v is not w and v.get("fault") != w.get("fault") and float(v["start"]) < b and a < float(v["stop"])
                     for v in windows)  # fmt: skip
    if not size or overlapped:
        return
    where = window_label(w)
    for k, s in enumerate(size):
        if not s or k >= len(ftc) or ftc[k] is None or not ftc[k] > SENSOR_MOTION * s:
            continue
        name = outputs[k] if k < len(outputs) else f"output {k}"
        unit = f" {units[k]}" if k < len(units) and units[k] else ""
        without = f", {none[k]:.3g}{unit} without" if k < len(none) and none[k] is not None else ""
        add("sensor fault moves the plant", f"{where}, {name}", ftc[k] / s,
            f"in {where} the sensor fault moves the plant more than it misreads it: a fault of {s:.3g}{unit} on the "
            f"reading of {name} moves the TRUE {name} by {ftc[k]:.3g}{unit} RMS over the window ({ftc[k] / s:.3g} x "
            f"the fault) with tolerant control{without}. The fault enters only the measurement: the plant moves "
            "because u follows the observer's estimate, which the fault throws off")  # fmt: skip


def _window_verdicts(m: dict, w: dict, add, inputs) -> None:
    """Window ``w``'s estimate (poor, too slow an observer, not settled), detection (missed, a standing alarm)
    and inputs (saturated)."""
    where = window_label(w)
    err, err_iv = w.get("fault_rel_rms_error"), w.get("fault_rel_rms_error_interval")
    if err is not None and err >= POOR_ESTIMATE and (err_iv is None or err_iv[0] >= POOR_ESTIMATE):
        add("poor estimate", where, err,
            f"in {where} the fault estimate misses {100 * min(err, 9.99):.0f} % of the fault (relative RMS error "
            f"{err:.3g} over the window): this design does not estimate this fault in this scenario")  # fmt: skip
    tau = m.get("observer_time_constant")
    span = float(w["stop"]) - float(w["start"])
    if tau is not None and SLOW_OBSERVER * tau > span:
        add("slow observer", where, tau,
            f"the observer's slowest time constant {tau:.3g} is too slow for {where}: {SLOW_OBSERVER:g} time "
            f"constants ({SLOW_OBSERVER * tau:.3g}) are longer than the window ({span:.3g})")  # fmt: skip
    if w.get("fault_rel_rms_error") is not None and w.get("settling_time") is None:
        add("not settled", where, None,
            f"in {where} the fault estimate does not settle: its mean error over the paths is not within 10 % of "
            "the fault's peak by the window's end")  # fmt: skip
    miss = w.get("missed_detections")
    if miss:
        add("missed", where, miss,
            f"in {where} the fault is not detected on {miss} of {m.get('paths')} paths (the alarm off at its "
            "onset and never raised in it)")  # fmt: skip
    standing = w.get("standing_alarm_paths")
    if standing:
        add("standing alarm", where, standing,
            f"in {where} the alarm of {w['fault']} was already on at the onset on {standing} of {m.get('paths')} "
            "paths: a false alarm the fault found raised, counted as neither a detection nor a miss")  # fmt: skip
    for i, frac in enumerate(w.get("input_saturation", [])):
        if frac > SATURATED:
            name = inputs[i] if i < len(inputs) else str(i)
            add("saturated", where, frac,
                f"input {name} is at a limit for {100 * frac:.0f} % of {where}: the tolerance is that of a "
                "saturated actuator")  # fmt: skip


def design_warnings(checks: dict, alpha, scenario) -> list[str]:
    """What makes a certified design unfit for its scenario, seen before any simulation: an observer whose
    slowest time constant (``1 / |max Re eig R_i|``, from ``checks``) is too slow for the scenario's fault
    windows, and a decay rate lowered to 0 (``alpha``). Empty without a scenario or faults."""
    out = []
    if scenario is None or not scenario.faults:
        return out
    re = checks.get("R_max_real_eig")
    shortest = min(float(fp.stop) - float(fp.start) for fp in scenario.faults)
    if re is not None and re < 0 and SLOW_OBSERVER / -re > shortest:
        tau = 1.0 / -re
        out.append(
            f"the observer's slowest time constant is {tau:.3g}: {SLOW_OBSERVER:g} of them ({SLOW_OBSERVER * tau:.3g}) "
            f"are longer than the scenario's shortest fault window ({shortest:.3g}), so its fault estimates cannot "
            "settle inside the windows (fte design tries a larger kappa and, where the sample time lowered the decay "
            "rate, a shorter one, and prints what each gives; fte simulate measures what it costs)"
        )
    elif re is not None and re >= 0:
        out.append(f"the observer's slowest mode does not decay (max Re eig R_i = {re:.3g})")
    if alpha is not None and float(alpha) == 0.0 and scenario.faults:
        out.append(
            "the observer's decay rate alpha was lowered to 0 to certify the discrete step at this sample time: "
            "nothing certifies how fast the fault estimates converge; a shorter sample time allows a positive decay rate"
        )
    return out
