"""The verdicts on a metrics document (docs/interface.md), in one place.

``fte simulate`` warns by them, the report marks by them, ``fte tune`` chooses by them and
:func:`fte_casadi.design._limits.explain_metrics` explains the windows and faults they single out.
A module of its own (as :mod:`fte_casadi._rounding`), so that every step of the package can read them
without importing the simulator. Every verdict is judged on the figures measured on the true plant.
"""

from __future__ import annotations

__all__ = [
    "WORSE_THAN_NONE",
    "FALSE_ALARM",
    "SATURATED",
    "OUTSIDE_REGION",
    "POOR_ESTIMATE",
    "SLOW_OBSERVER",
    "verdicts",
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


def _where(w: dict) -> str:
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


def verdicts(m: dict, inputs=(), faults=(), outputs=(), units=()) -> list[dict]:
    """The verdicts on metrics document ``m``: a list of ``{"verdict", "where", "value", "text"}`` with
    ``verdict`` one of ``worse than none``, ``worse than none on an output``, ``false alarm``, ``saturated``,
    ``poor estimate``, ``slow observer``, ``not settled``, ``missed``, ``outside region``."""
    out = []

    def add(verdict, where, value, text):
        out.append({"verdict": verdict, "where": where, "value": value, "text": text})

    for name, v in zip(faults, m.get("false_alarm_peak") or ()):
        if v is not None and v >= FALSE_ALARM:
            add("false alarm", name, v,
                f"the estimate of {name} outside its fault windows peaks at {v:.3g} x the fault's own peak "
                f"(>= {FALSE_ALARM:g}): false alarms, e.g. cross-talk from another fault")  # fmt: skip
    for w in m.get("windows", []):
        where = _where(w)
        r = w.get("ftc_true_ratio")
        if r is not None and r > WORSE_THAN_NONE:
            per = w.get("ftc_true_ratio_per_output") or []
            worst = ", ".join(
                f"{outputs[k] if k < len(outputs) else k}: {v:.4g}"
                for k, v in enumerate(per)
                if v is not None
            )
            add("worse than none", where, r,
                f"in {where} tolerant control makes the TRUE outputs worse than none (ftc_true_ratio {r:.4g} > "
                f"{WORSE_THAN_NONE:g}; per output {worst}){_crosstalk(w, faults)}")  # fmt: skip
        elif r is not None:
            rms = w.get("ftc_true_rms_per_output") or {}
            for k, v in enumerate(w.get("ftc_true_ratio_per_output") or []):
                if v is not None and v > WORSE_THAN_NONE:
                    name = outputs[k] if k < len(outputs) else f"output {k}"
                    size = ""
                    if rms.get("ftc") and rms.get("no_ftc"):
                        unit = f" {units[k]}" if k < len(units) and units[k] else ""
                        size = (f": RMS deviation from the fault-free run {rms['ftc'][k]:.3g}{unit} with it against "
                                f"{rms['no_ftc'][k]:.3g}{unit} without")  # fmt: skip
                    add("worse than none on an output", f"{where}, {name}", v,
                        f"in {where} tolerant control makes the true output {name} worse than none (ratio {v:.4g} > "
                        f"{WORSE_THAN_NONE:g}{size}), though the outputs as a whole are better (ftc_true_ratio "
                        f"{r:.3g}){_crosstalk(w, faults)}")  # fmt: skip
        err = w.get("fault_rel_rms_error")
        if err is not None and err >= POOR_ESTIMATE:
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
            add(
                "missed",
                where,
                miss,
                f"in {where} the fault is not detected on {miss} of {m.get('paths')} paths",
            )
        for i, frac in enumerate(w.get("input_saturation", [])):
            if frac > SATURATED:
                name = inputs[i] if i < len(inputs) else str(i)
                add("saturated", where, frac,
                    f"input {name} is at a limit for {100 * frac:.0f} % of {where}: the tolerance is that of a "
                    "saturated actuator")  # fmt: skip
    frac = m.get("outside_region")
    if frac is not None and frac > OUTSIDE_REGION:
        add("outside region", "run", frac,
            f"{100 * frac:.1f} % of the samples leave the plant's region, where the T-S model (and the design's "
            "certificate) is not exact")  # fmt: skip
    return out


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
