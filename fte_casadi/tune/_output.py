"""What ``fte tune`` writes: the front as documents, the chosen design, the record of every trial,
and the rows of the default-vs-chosen comparison."""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path

from .._atomic import atomic_write_text, replace_dir
from ..design import Design
from ..errors import ParameterError

__all__ = ["comparison"]  # public: docs/api.md

#: the key that marks a tune.json as written by fte tune
MARKER = "fte_tune"


def is_tune_record(path: Path) -> bool:
    """True when ``path`` is a tune.json that fte tune wrote."""
    try:
        doc = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, ValueError):
        return False
    return isinstance(doc, dict) and MARKER in doc


def _design_name(number: int) -> str:
    return f"trial-{number:04d}.json"


def front_documents(result, out_dir: str | None) -> list[dict]:
    """The front as the contract's list ``{"params", "metrics", "design": FILE}`` (FILE None without
    an output directory), best first by the chosen rule's order (the chosen design first)."""
    order = [result.chosen] + [k for k in result.front if k != result.chosen]
    out = []
    for k in order:
        r = result.record(k)
        f = None if out_dir is None else str(Path(out_dir) / "designs" / _design_name(k))
        out.append({"trial": k, "params": r.params, "knobs": _jsonable(r.knobs), "metrics": r.metrics,
                    "objectives": dict(zip(result.objectives, r.values)), "design": f,
                    "chosen": k == result.chosen})  # fmt: skip
    return out


def _jsonable(d: dict) -> dict:
    return {k: (bool(v) if isinstance(v, bool) else float(v)) for k, v in d.items()}


def write_outputs(result, out_dir: str, work: str | os.PathLike | None = None) -> dict:
    """Write ``DIR/tuned.json`` (the chosen design), ``DIR/designs/trial-NNNN.json`` (each front
    member), ``DIR/tune.json`` (every trial: knobs, params, objectives or the reason it failed; the
    rule, the front, the limits) and ``DIR/pareto.png``, as one set: into the folder ``work`` (default:
    a new one beside DIR), which then takes DIR's place (:func:`fte_casadi._atomic.replace_dir`). A
    failure or a kill at any moment leaves the previous DIR as it was, or the complete new one; what
    else ``work`` holds (``fte tune``'s optuna.db) comes along. The caller has checked that DIR holds
    nothing fte tune did not write. Returns the paths, in DIR."""

    out = Path(out_dir)
    made = work is None
    if made:
        out.resolve().parent.mkdir(parents=True, exist_ok=True)
        work = tempfile.mkdtemp(prefix=f".{out.resolve().name}.", suffix=".new", dir=out.resolve().parent)
    w = Path(work)
    try:
        _write_set(result, w)
        replace_dir(w, out)
    except BaseException as exc:
        if made:
            shutil.rmtree(w, ignore_errors=True)
        if isinstance(exc, OSError):
            raise ParameterError(f"cannot write the results of fte tune into {out}: {exc.strerror or exc}; {out} is "
                                 "as it was") from None  # fmt: skip
        raise
    return {"tuned": out / "tuned.json", "record": out / "tune.json", "figure": out / "pareto.png",
            "designs": out / "designs"}  # fmt: skip


def _write_set(result, w: Path) -> None:
    from ..plot import pareto_figure

    designs = w / "designs"
    if designs.exists():  # an earlier attempt's, in the same work folder
        shutil.rmtree(designs)
    designs.mkdir(parents=True)
    for k in result.front:
        atomic_write_text(designs / _design_name(k), result.record(k).design)
    Design.from_dict(json.loads(result.record(result.chosen).design)).save(w / "tuned.json")
    record = {
        MARKER: 1,
        "plant": result.plant,
        "seed": result.seed,
        "paths": result.paths,
        "rule": result.rule,
        "tier": result.tier,
        "objectives": list(result.objectives),
        "space": {k: list(v) for k, v in result.space.items()},
        "front": list(result.front),
        "chosen": result.chosen,
        "limits": list(result.limits),
        "wall_s": result.wall_s,
        "trials": [
            {
                "trial": r.number,
                "state": r.state,
                "knobs": _jsonable(r.knobs),
                "params": r.params,
                "objectives": None if r.values is None else dict(zip(result.objectives, r.values)),
                "metrics": r.metrics,
                "reason": r.reason,
            }
            for r in result.records
        ],  # fmt: skip
    }
    atomic_write_text(w / "tune.json", json.dumps(record, indent=1))
    pareto_figure(result, w)


def _fmt(v) -> str:
    return "n/a" if v is None else f"{v:.3g}"


def comparison(
    base: dict, chosen: dict, fault_names, input_names, output_names=()
) -> list[tuple[str, float | None, float | None]]:
    """``(metric, default, chosen)`` rows over every metric of the issue's table, each window's FTC ratio on each
    output (named by ``output_names``), the same after each window where both documents measured it
    (``after_window``), and the inputs."""
    rows = []
    for j, f in enumerate(fault_names):
        rows.append((f"fault error {f}", base["fault_rel_rms_error"][j], chosen["fault_rel_rms_error"][j]))
    for j, f in enumerate(fault_names):
        rows.append((f"false alarms {f}", base["false_alarm_peak"][j], chosen["false_alarm_peak"][j]))
    for wb, wc in zip(base["windows"], chosen["windows"]):
        tag = f"{wb['fault']} [{wb['start']:g}, {wb['stop']:g})"
        rows.append((f"fault error in window {tag}", wb["fault_rel_rms_error"], wc["fault_rel_rms_error"]))
        rows.append((f"FTC ratio in window {tag}", wb["ftc_true_ratio"], wc["ftc_true_ratio"]))
        for k, (b, c) in enumerate(zip(wb.get("ftc_true_ratio_per_output") or [],
                                       wc.get("ftc_true_ratio_per_output") or [])):  # fmt: skip
            name = output_names[k] if k < len(output_names) else f"output {k}"
            rows.append((f"FTC ratio in window {tag}, {name}", b, c))
        ab, ac = wb.get("after_window"), wc.get("after_window")
        if ab and ac:  # the span after the window, up to the next (no fault in the plant)
            rows.append((f"FTC ratio after window {tag}", ab["ftc_true_ratio"], ac["ftc_true_ratio"]))
            for k, (b, c) in enumerate(zip(ab["ftc_true_ratio_per_output"], ac["ftc_true_ratio_per_output"])):
                name = output_names[k] if k < len(output_names) else f"output {k}"
                rows.append((f"FTC ratio after window {tag}, {name}", b, c))
    rows.append(("FTC ratio, all windows", base["ftc_true_ratio"], chosen["ftc_true_ratio"]))
    for i, u in enumerate(input_names):
        rows.append((f"peak |{u}|", base["input_peak"][i], chosen["input_peak"][i]))
        rows.append((f"saturation {u}", base["input_saturation"][i], chosen["input_saturation"][i]))
    if base.get("fault_error_bound") is not None:
        rows.append(
            (
                "certified bound (L2 gain to f - fhat)",
                base["fault_error_bound"],
                chosen.get("fault_error_bound"),
            )
        )
    for i, v in enumerate(base["state_rms_error"]):
        rows.append((f"state RMS error {i + 1}", v, chosen["state_rms_error"][i]))
    return rows


def dominates(rows) -> bool:
    """True when the chosen design is at least as good as the default on every row of :func:`comparison`
    that concerns faults (errors, false alarms, FTC ratios; the inputs and states are trade-offs shown)."""
    keys = ("fault error", "false alarms", "FTC ratio")
    return all(c <= b for name, b, c in rows if name.startswith(keys) and b is not None and c is not None)


def fmt_rows(rows) -> list[str]:
    width = max(len(r[0]) for r in rows) if rows else 10
    out = [f"{'metric':<{width}} {'default':>10} {'chosen':>10}"]
    for name, b, c in rows:
        mark = "" if b is None or c is None else (" better" if c < b else (" worse" if c > b else ""))
        out.append(f"{name:<{width}} {_fmt(b):>10} {_fmt(c):>10}{mark}")
    return out


def front_table(result) -> list[str]:
    """The front as table rows (the chosen design first, marked *; the base marked d)."""
    cols = [("gamma", "gamma"), ("gamma1", "gamma1"), ("sigma", "sigma"), ("alpha", "alpha"), ("kappa", "kappa"),
            ("epsilon", "eps"), ("boundary_layer", "phi")]  # fmt: skip
    short = [n.replace("fault_error", "err").replace("false_alarm", "fa")
             .replace("input_peak", "u_peak").replace("input_saturation", "u_sat")
             .replace("bound[fault_error]", "bound") for n in result.objectives]  # fmt: skip
    w = max(8, *(len(s) for s in short))
    lines = [
        f"{'trial':>6} " + " ".join(f"{h:>8}" for _, h in cols) + " " + " ".join(f"{s:>{w}}" for s in short)
    ]
    order = [result.chosen] + [k for k in result.front if k != result.chosen]
    for k in order:
        r = result.record(k)
        tag = ("*" if k == result.chosen else "") + ("d" if k == 0 else "")
        cells = ["-" if r.params.get(c) is None else format(r.params[c], ".3g") for c, _ in cols]
        lines.append(f"{str(k) + tag:>6} " + " ".join(f"{c:>8}" for c in cells) + " "
                     + " ".join(f"{v:>{w}.3g}" for v in r.values))  # fmt: skip
    return lines
