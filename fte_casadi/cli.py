"""The ``fte`` command: the only place that prints or exits.

Every command turns the library's errors into a one-paragraph message and exit status 2
(bad input) or 1 (a failed design/run); ``--debug`` shows the Python traceback instead.
"""

from __future__ import annotations

import functools
import json
import re
import sys
import textwrap
import time
from pathlib import Path

import click
import numpy as np
from tqdm import tqdm

from .errors import FteError, InfeasibleDesignError, ParameterError, SolverFailedError

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> None:
    click.echo(
        textwrap.fill("fte: " + " ".join(message.split()), width=100, break_on_hyphens=False), err=True
    )
    sys.exit(code)


def _ours(path: Path) -> bool:
    """True when ``path`` holds something fte wrote: a design document (JSON or MAT) or a saved result (.npz)."""
    import zipfile

    from .design.record import REQUIRED_KEYS

    if path.suffix.lower() == ".mat":
        from .design.matfile import is_fte_mat

        return is_fte_mat(path)
    try:
        if zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as z:
                return {"meta.npy", "design.npy", "scenario.npy"} <= set(z.namelist())
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, zipfile.BadZipFile):
        return False
    return isinstance(doc, dict) and all(k in doc for k in REQUIRED_KEYS)


def _writable_target(path: str, option: str, what: str) -> None:
    """Refuse, before any work, to overwrite a file fte did not write (a plant file, a user's data);
    a directory gets a hint. An earlier fte output is replaced, as ``-o`` promises."""
    p = Path(path)
    if p.is_dir():
        raise ParameterError(f"{option} {path} is a directory; give a file name such as {p / what}")
    if p.exists() and not _ours(p):
        raise ParameterError(
            f"{option} {path} exists and was not written by fte (it is not a {what.split('.')[0]} document): it is "
            "left untouched; choose another file name, or move that file away first"
        )


def _stat_tree(path: Path) -> dict[str, tuple]:
    """Every file at or under ``path``: its identity, time and size (a file renamed into place is a new identity)."""
    out = {}
    try:
        for f in [path] if path.is_file() else path.rglob("*") if path.is_dir() else []:
            if f.is_file():
                st = f.stat()
                out[str(f)] = (st.st_ino, st.st_mtime_ns, st.st_size)
    except OSError:
        pass
    return out


def _outputs(*targets) -> None:
    """Note the files and folders this command may write: after a Ctrl-C the message lists exactly
    those of them that changed (each complete: every file is renamed into place whole)."""
    meta = click.get_current_context().meta.setdefault("fte.outputs", {})
    for t in targets:
        if t is not None and Path(t) not in meta:
            meta[Path(t)] = _stat_tree(Path(t))


def _interrupted() -> str:
    """What was written before a Ctrl-C, from the snapshot :func:`_outputs` took, and what to do next."""
    ctx = click.get_current_context()
    written, removed = [], []
    for path, before in ctx.meta.get("fte.outputs", {}).items():
        after = _stat_tree(path)
        written += sorted(f for f, v in after.items() if before.get(f) != v)
        removed += sorted(f for f in before if f not in after)

    def some(names: list[str]) -> str:
        return ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")

    parts = [f"written before the interrupt, each file complete: {some(written)}"] if written else []
    parts += [f"removed: {some(removed)}"] if removed else []
    if parts:
        msg = "interrupted; " + "; ".join(parts) + "; nothing else was written"
    else:
        msg = "interrupted; nothing was written (earlier files are as they were)"
    note = ctx.meta.get("fte.on_interrupt")
    return msg + (f"; {note()}" if note else "")


def _guard(fn):
    """Run a command; on a known error print one paragraph and exit non-zero (130 after a Ctrl-C,
    saying exactly which files were written)."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        debug = click.get_current_context().find_root().params.get("debug", False)
        try:
            return fn(*args, **kwargs)
        except (InfeasibleDesignError, SolverFailedError) as exc:
            if debug:
                raise
            _fail(str(exc), EXIT_FAILED)
        except FteError as exc:
            if debug:
                raise
            _fail(str(exc), EXIT_BAD_INPUT)
        except BrokenPipeError:  # output piped into `head` and the like
            sys.stderr.close()
            sys.exit(0)
        except KeyboardInterrupt:
            _fail(_interrupted(), 130)
        except MemoryError:
            if debug:
                raise
            _fail("out of memory: the run asks for more than this machine has; use fewer --paths (or a cluster "
                  "with --scheduler), or leave out --save")  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - the last line of defence: no traceback for users
            if debug:
                raise
            _fail(
                f"internal error {type(exc).__name__}: {exc}. This is a bug in fte_casadi or an unexpected "
                "input; run again with `fte --debug ...` to see where, and report it",
                3,
            )

    return wrapper


def _check_seed(seed: int) -> None:
    """A seed numpy's generators take: 0 <= seed < 2**63."""
    if not 0 <= seed < 2**63:
        raise ParameterError(f"--seed must be an integer from 0 to 2**63 - 1 = {2**63 - 1}; got {seed}")


def _positive(name: str, value, allow_zero: bool = False):
    if value is None:
        return None
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        what = "a finite number >= 0" if allow_zero else "a positive finite number"
        raise ParameterError(f"--{name.replace('_', '-')} must be {what}; got {value}")
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, help="Show Python tracebacks on errors.")
@click.version_option(package_name="fte_casadi")
def main(debug: bool) -> None:
    """fte: certified fault estimation and fault-tolerant control, from CasADi equations to embedded C.

    PLANT is a built-in name (manipulator, three-tank, quadruple-tank), path/to/file.py:function or
    package.module:function returning a Plant.
    """


# -- derive -------------------------------------------------------------------------------
def _fmt_matrix(M: np.ndarray, indent: str = "    ") -> str:
    M = np.atleast_2d(M)
    if M.size == 0:
        return indent + "[]"
    rows = [" ".join(f"{v:>10.5g}" for v in row) for row in M]
    return "\n".join(indent + r for r in rows)


_VERTICES = click.option(
    "--vertices", type=click.Choice(["grouped", "box", "fewest"]), default=None,
    help="How the premises of a sector model are covered: grouped (premises that depend on the same states "
    "together, a simplex or a box per group, whichever has fewer vertices; the default for premises found "
    "automatically), box (each premise its own sector: 2^q rules, the most vertices; the default for declared "
    "premises), fewest (one simplex over all premises: q + 1 rules, the loosest).",
)  # fmt: skip


@main.command()
@click.argument("plant")
@click.option("--json", "as_json", is_flag=True, help="Print the derive document (JSON) on stdout.")
@_VERTICES
@_guard
def derive(plant: str, as_json: bool, vertices: str | None) -> None:
    """Derive the T-S fuzzy model of PLANT and check its fidelity."""
    from .plants.loader import load_plant
    from .ts import derive as derive_ts

    p = load_plant(plant)
    ts = derive_ts(p, vertices=vertices)
    if as_json:
        click.echo(json.dumps(ts.to_dict(), indent=1))
        return
    click.echo(
        f"plant {p.name}: n = {ts.n} states, m = {ts.m} inputs, p = {ts.p} outputs, "
        f"ld = {ts.ld} unknown inputs, lf = {ts.lf} faults; {ts.r} rules by {ts.method}"
    )
    click.echo("premises:")
    for pr in ts.premises:
        gap = f" (bounds widened by {pr.bound_gap:.2g})" if pr.bound_gap else ""
        click.echo(f"  {pr.name} = {pr.expr}: [{pr.min:.6g}, {pr.max:.6g}]{gap}")
    for note in ts.notes:  # how the automatic method found them
        click.echo(f"  {note}")
    for i, lm in enumerate(ts.local_models):
        click.echo(f"rule {i + 1}:")
        for key in ("A", "B", "Bd", "Bf", "W"):
            click.echo(f"  {key} =\n{_fmt_matrix(getattr(lm, key))}")
        if np.any(lm.a):
            click.echo(f"  a (affine offset) = {np.array2string(lm.a, precision=5)}")
        if lm.has_diffusion_extension:
            for key in ("G", "Gf", "M"):
                click.echo(f"  {key} =\n{_fmt_matrix(getattr(lm, key))}")
    click.echo(f"C =\n{_fmt_matrix(ts.C, '  ')}\nDf =\n{_fmt_matrix(ts.Df, '  ')}")
    f = ts.fidelity
    click.echo(
        f"fidelity over {f.samples} samples of the region: max |error| = {f.max_abs_error:.3g} "
        f"(drift {f.drift_max_abs_error:.3g}, {100 * f.drift_max_rel_error:.3g} % of its largest value; "
        f"diffusion {f.diffusion_max_abs_error:.3g}); along a {f.trajectory_horizon:.4g} {p.time_unit} "
        f"trajectory: {f.trajectory_max_abs_error:.3g}"
        + (f" (stopped early: {f.trajectory_stop})" if f.trajectory_stop else "")
    )


# -- design -------------------------------------------------------------------------------
def _check_params(**kw) -> dict:
    out = {}
    for k, v in kw.items():
        if v is not None:
            _positive(k, v, allow_zero=(k in ("alpha", "d_bound", "bound_weight")))
            out[k] = v
    return out


def _scenario(plant_spec: str):
    """The plant's scenario, or None when it has none."""
    from .errors import PlantLoadError
    from .plants.loader import load_scenario

    try:
        return load_scenario(plant_spec)
    except PlantLoadError:
        return None


def _scenario_sample_time(plant_spec: str) -> float | None:
    """The sample time a design is made for: the plant's scenario step (``Scenario.dt``, the step
    ``fte simulate`` runs the controller at), when the plant has a scenario."""
    sc = _scenario(plant_spec)
    return None if sc is None else float(sc.dt)


def _absolute_spec(plant_spec: str) -> str:
    """A ``file.py:function`` spec with the file's absolute path, so documents work from any directory."""
    if ":" in plant_spec and plant_spec.rsplit(":", 1)[0].endswith(".py"):
        target, func = plant_spec.rsplit(":", 1)
        return f"{Path(target).resolve()}:{func}"
    return plant_spec


def _make_design(
    plant_spec: str, variant: str, solver: str, params: dict, allow_uncertified: bool = False, accept=(),
    vertices: str | None = None,
):  # fmt: skip
    from .design import DesignOptions
    from .design import design as run_design
    from .plants.loader import load_plant
    from .ts import derive as derive_ts

    options = DesignOptions(variant=variant, solver=solver, allow_uncertified=allow_uncertified,
                            accept_assumptions=tuple(accept), plant_spec=_absolute_spec(plant_spec), **params)  # fmt: skip
    ts = derive_ts(load_plant(plant_spec), vertices=vertices)
    sc = _scenario(plant_spec)
    if options.sample_time is None and sc is not None:
        options = options.replace(sample_time=float(sc.dt))
    if sc is not None and sc.x0 is not None:  # the simulation's nominal start, for the C's init_from_y
        options = options.replace(initial_state=sc.x0)
    return run_design(ts, options)


def _explore(plant_spec: str, solver: str, gamma1, out_dir: str) -> None:
    from .design import explore
    from .plants.loader import load_plant
    from .plot import frontier_figure
    from .ts import derive as derive_ts

    ts = derive_ts(load_plant(plant_spec))
    with tqdm(total=12, desc=f"explore {ts.plant.name}", unit=" sigma", file=sys.stderr, delay=1.0) as bar:
        points, info = explore(ts, solver=solver, gamma1=gamma1, sample_time=_scenario_sample_time(plant_spec),
                               progress=lambda k, n: bar.update(1))  # fmt: skip
    click.echo(
        f"feasible frontier of {ts.plant.name} (gamma1 = {info['gamma1']:g}; (45) is feasible for any gamma only with "
        f"sigma < {info['sigma_sup']:.4g}); the plant's defaults: gamma = {info['gamma']:g}, sigma = {info['sigma']:g}"
    )
    click.echo(
        f"{'sigma':>10} {'gamma_min (45)':>15} {'certified from':>15} {'alpha':>9} {'max|L1|':>9} {'ts_max':>9}"
    )
    for pt in points:
        click.echo(
            f"{pt.sigma:10.4g} {'-' if pt.gamma_min is None else format(pt.gamma_min, '.4g'):>15} "
            f"{'-' if pt.gamma_tried is None else format(pt.gamma_tried, 'g'):>15} "
            f"{'-' if pt.alpha is None else format(pt.alpha, '.3g'):>9} "
            f"{'-' if pt.max_abs_L1 is None else format(pt.max_abs_L1, '.3g'):>9} "
            f"{'-' if pt.ts_max is None else format(pt.ts_max, '.3g'):>9}"
            + (f"  {pt.note}" if pt.note and not pt.certified else "")
        )
    fig = frontier_figure(points, info, ts.plant.name, out_dir)
    click.echo(f"figure written to {fig}")


@main.command()
@click.argument("plant")
@click.option(
    "--variant",
    type=click.Choice(["paper", "conditioned"]),
    default="conditioned",
    show_default=True,
    help="paper: the problem as printed; conditioned: the same certificate posed with usable numbers.",
)
@click.option("--solver", default="CLARABEL", show_default=True, help="SDP solver: CLARABEL or SCS.")
@click.option(
    "--gamma", type=float, help="H-infinity level gamma (default: the plant's, the paper's for built-ins)."
)
@click.option("--gamma1", type=float, help="gamma1 < gamma.")
@click.option("--sigma", type=float, help="sigma of Theorem 2.")
@click.option("--delta", type=float, help="bound on the second derivative of the faults.")
@click.option("--epsilon", type=float, help="sliding gain margin eps.")
@click.option(
    "--alpha",
    type=float,
    help="observer decay rate (default: the largest the plant allows, see docs/design.md).",
)
@click.option(
    "--sample-time", "sample_time", type=float,
    help="sample time the observer must run at (default: the plant's scenario step); caps the default alpha.",
)  # fmt: skip
@click.option(
    "--bound-weight", "bound_weight", type=float,
    help="Weight of the closed loop's fault-error bound in the observer's objective (default 0: off; 1 counts it "
    "as much as the rest; docs/design.md).",
)  # fmt: skip
@click.option(
    "--allow-uncertified", is_flag=True, help="Write the design even when a certificate fails (marked so)."
)
@click.option(
    "--accept-assumption", "accept", multiple=True, type=click.Choice(["1", "2", "3", "4", "5"]),
    help="Design even though assumption N of Section 3 fails (repeatable; the document records it).",
)  # fmt: skip
@click.option(
    "--no-remark5",
    "no_remark5",
    is_flag=True,
    help="Refuse a plant whose unknown inputs H cannot decouple (assumption (1)) instead of applying Remark 5.",
)
@click.option(
    "--d-bound", "d_bound", type=float,
    help="With Remark 5: a bound on |d| for the sliding gain of the undecoupled unknown inputs (default: delta).",
)  # fmt: skip
@click.option(
    "-o", "--output", type=click.Path(dir_okay=False), help="Write the design document (JSON) here."
)
@click.option(
    "--explore", is_flag=True, help="Print and plot the feasible frontier (smallest gamma over sigma)."
)
@_VERTICES
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="With --explore: the directory of the frontier figure (default: fte-explore).")  # fmt: skip
@_guard
def design(plant, variant, solver, gamma, gamma1, sigma, delta, epsilon, alpha, sample_time, bound_weight,
           allow_uncertified, accept, no_remark5, d_bound, output, explore, out_dir, vertices):  # fmt: skip
    """Design the observer and tolerant controller of PLANT by LMIs, with certificates."""
    params = _check_params(gamma=gamma, gamma1=gamma1, sigma=sigma, delta=delta, epsilon=epsilon, alpha=alpha,
                           sample_time=sample_time, d_bound=d_bound, bound_weight=bound_weight)  # fmt: skip
    if no_remark5:
        params["remark5"] = False
    if explore:
        _outputs(out_dir or "fte-explore")
        _explore(plant, solver.upper(), gamma1, out_dir or "fte-explore")
        return
    if out_dir is not None:
        raise ParameterError(
            f"--out {out_dir} is the directory of --explore's figure; to write the design document use -o FILE"
        )
    if output is not None:
        _writable_target(output, "-o", "design.json")
    _outputs(output)
    d = _make_design(plant, variant, solver.upper(), params, allow_uncertified, accept, vertices)
    from .design.summary import design_summary

    click.echo(design_summary(d))
    from .verdicts import design_warnings

    for w in design_warnings(d.checks, d.observer.alpha, _scenario(plant)):
        click.echo(textwrap.fill("fte: warning: " + w, width=100), err=True)
    if output:
        if Path(output).suffix.lower() == ".mat":
            d.save_mat(output)
            click.echo(
                f"design document written to {output} (MAT file: every matrix under its contract name)"
            )
        else:
            d.save(output)
            click.echo(f"design document written to {output}")
    else:
        click.echo("(design document not saved: add -o FILE)")


def _design_or_plant(
    target: str, progress: bool = True, plant: str | None = None, allow_uncertified: bool = False
):
    """A design document path, or a plant spec designed on the fly (conditioned variant).

    A document is checked before use (:func:`fte_casadi.trust.check_loaded`): re-certified at its numbers,
    against its plant when that is a built-in one or named with ``plant`` (--plant), never running code it
    names. Returns ``(design, plant spec or None)``: the spec of the plant it may be simulated on.
    """
    from .design.record import Design
    from .trust import check_loaded

    p = Path(target)
    if target.endswith(".json") or p.is_file():
        trusted = check_loaded(Design.load(p), plant, allow_uncertified)
        for note in trusted.notes:
            click.echo(textwrap.fill("fte: " + note, width=100, break_on_hyphens=False), err=True)
        return trusted.design, trusted.plant_spec
    if plant is not None:
        raise ParameterError(
            f"--plant names the plant of a design document; {target} is a plant: give one of them"
        )
    if progress:
        click.echo(f"designing {target} (conditioned variant) ...", err=True)
    return _make_design(target, "conditioned", "CLARABEL", {}), target


def _need_plant(d, spec: str | None, command: str) -> str:
    """The plant spec ``command`` simulates ``d`` on; a document's own non-built-in spec is not imported."""
    if spec is None:
        raise ParameterError(
            f"fte {command} simulates the true nonlinear plant, and the document names {d.plant_spec!r}, which fte does "
            f"not import on a document's word (it would run that code): name the plant yourself with "
            f"--plant {d.plant_spec} if you trust it"
        )
    return spec


_plant_option = click.option(
    "--plant", "plant_opt", metavar="PLANT",
    help="The plant of a design document (built-in name, FILE.py:FUNCTION or module:function): checked against "
    "the document; needed to simulate a document whose plant is not a built-in one (docs/interface.md, Trust model).",
)  # fmt: skip
_allow_option = click.option(
    "--allow-uncertified", "allow_uncertified", is_flag=True,
    help="Use a design document that does not re-certify at its own numbers (marked NOT CERTIFIED).",
)  # fmt: skip


# -- codegen ------------------------------------------------------------------------------
@main.command()
@click.argument("target", metavar="DESIGN.json|PLANT")
@click.option(
    "--out", "out_dir", required=True, type=click.Path(file_okay=False), help="Directory for the C files."
)
@click.option(
    "--sample-time", "sample_time", type=float,
    help="Sample time (default: the one the design was made for and fte simulate runs, its scenario's step; "
    "without one, a tenth of the design's ts_max, rounded down).",
)  # fmt: skip
@click.option("--ts", "sample_time_alias", type=float, hidden=True)  # the name before 0.2.0
@click.option("--real", type=click.Choice(["double", "float"]), default="double", show_default=True)
@click.option("--boundary-layer", type=float, help="Replace sgn(s) by sat(s/PHI).")
@click.option("--fmu", is_flag=True, help="Also write DIR/PLANT.fmu, an FMI 2.0 co-simulation FMU.")
@_plant_option
@_allow_option
@_guard
def codegen(
    target, out_dir, sample_time, sample_time_alias, real, boundary_layer, fmu, plant_opt, allow_uncertified
):
    """Generate the embedded C of the observer/controller step."""
    from .codegen import default_sample_time, generate_c
    from .codegen.fmu import check_fmu_target, generate_fmu
    from .plants import SCENARIOS

    if sample_time is not None and sample_time_alias is not None:
        raise click.UsageError("give the sample time once: --sample-time (--ts is its former name)")
    sample_time = sample_time if sample_time_alias is None else sample_time_alias
    _positive("sample-time", sample_time)
    _positive("boundary-layer", boundary_layer)
    _outputs(out_dir)
    d, _ = _design_or_plant(target, plant=plant_opt, allow_uncertified=allow_uncertified)
    if fmu:
        check_fmu_target(d, out_dir)  # a compiler, and no foreign file in the way, before any work
    made_for = default_sample_time(d, SCENARIOS[d.plant]().dt if d.plant in SCENARIOS else None)
    files = generate_c(d, out_dir, sample_time=made_for if sample_time is None else sample_time, real=real,
                       boundary_layer=boundary_layer)  # fmt: skip
    how = (
        "--sample-time" if sample_time is not None else "the design's sample time, the step fte simulate runs"
    )
    if sample_time is not None and abs(sample_time - made_for) > 1e-12 * sample_time:
        how += f"; the design was made for {made_for:g}"
    if sample_time is None:
        sample_time = made_for
    click.echo(f"wrote {len(files)} files into {out_dir}: " + ", ".join(f.name for f in files))
    click.echo(f"sample time Ts = {sample_time:g} ({how})")
    click.echo(f"compile with: cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic {out_dir}/*.c your_main.c -lm")
    if fmu:
        path = generate_fmu(d, out_dir, sample_time=sample_time, real=real, boundary_layer=boundary_layer)
        click.echo(f"wrote {path}: FMI 2.0 co-simulation FMU, fixed step Ts = {sample_time:g} (docs/fmu.md)")


# -- simulate -----------------------------------------------------------------------------
def _fmt_list(v) -> str:
    return "[" + ", ".join("n/a" if x is None else f"{x:.3g}" for x in v) + "]"


def _with_noise(scenario, noise: str | None):
    """The scenario with ``--measurement-noise`` (comma-separated standard deviations) when given."""
    if not noise:
        return scenario
    import dataclasses

    try:
        stds = [float(v) for v in noise.split(",")]
    except ValueError:
        raise ParameterError(
            f"--measurement-noise {noise!r}: give one standard deviation per output, comma-separated (e.g. 0.01,0,0.02)"
        ) from None
    return dataclasses.replace(scenario, measurement_noise=tuple(stds))


def _summary(plant: str, m: dict) -> str:
    """The metrics document in words (docs/interface.md gives each formula)."""
    lines = [
        f"{plant}: {m['paths']} paths x 3 runs, T = {m['T']:g}, dt = {m['dt']:g}, seed {m['seed']}, {m['wall_s']:.2f} s",
        f"  allowances: start-up transient {m['transient']:.4g}, after each window {m['settle_after']:.4g}",
        f"  state RMS error (t >= transient, FTC run): {_fmt_list(m['state_rms_error'])}",
        f"  fault error, relative RMS over whole windows: {_fmt_list(m['fault_rel_rms_error'])} "
        f"(settled part, each window minus its first 20 %: {_fmt_list(m['fault_rel_rms_error_settled'])})",
        f"  false alarms, estimate outside its windows: peak / fault's peak {_fmt_list(m['false_alarm_peak'])}, "
        f"relative RMS {_fmt_list(m['false_alarm_rel_rms'])}",
        f"  tolerant control, true outputs C x (ftc_true_ratio, < 1: better than none): {_num(m['ftc_true_ratio'])}; "
        f"compensated reading yc (ftc_compensated_ratio, estimation only): {_num(m['ftc_compensated_ratio'])}",
    ]
    for e in m.get("detection") or []:
        lines.append(
            f"  detection of {e['fault']}: threshold {_num(e['threshold'])}, false alarms per unit time "
            f"{_num(e['false_alarm_rate'])} on fault-free paths (asked {_num(e['false_alarm_rate_asked'])}), "
            f"{_num(e.get('false_alarm_rate_ftc_run'))} outside its windows with the other faults"
        )
    if m.get("measurement_noise") is not None:
        lines.append(f"  measurement noise (std per output): {_fmt_list(m['measurement_noise'])}")
    lines.append(f"  samples outside the plant's region: {100 * m['outside_region']:.2g} %")
    lines.append(f"  inputs at a limit (FTC run): {_fmt_list(m['input_saturation'])}")
    return "\n".join(lines)


def _num(v, fmt: str = ".3g") -> str:
    return "n/a" if v is None else format(v, fmt)


def _window_lines(m: dict) -> list[str]:
    """Per fault window: its estimation error, settling, detection and tolerant-control figures."""
    out = []
    for w in m.get("windows", []):
        det = w.get("detection_delay")
        miss = w.get("missed_detections")
        out.append(
            f"  window {w['fault']} [{w['start']:g}, {w['stop']:g}): fault error (relative RMS, whole window) "
            f"{_num(w['fault_rel_rms_error'])}, settled part {_num(w.get('fault_rel_rms_error_settled'))}, "
            f"settling time {_num(w.get('settling_time'))}; FTC true ratio {_num(w.get('ftc_true_ratio'))} "
            f"(per output {_fmt_list(w.get('ftc_true_ratio_per_output') or [])}), compensated "
            f"{_num(w.get('ftc_compensated_ratio'))}"
            + ("" if miss is None else f"; detected after {_num(det)} on average, missed on {miss} paths")
        )
    return out


def _warnings(m: dict, inputs, faults=(), outputs=(), units=()) -> list[str]:
    """The verdicts of :func:`fte_casadi.verdicts.verdicts`, as warnings."""
    from .verdicts import verdicts

    return ["warning: " + v["text"] for v in verdicts(m, inputs, faults, outputs, units)]


def _why(d, m: dict) -> list[str]:
    """The structural cause behind a window where tolerant control is worse than none, or behind false
    alarms (:func:`fte_casadi.design.limits.explain_metrics`)."""
    from .design.limits import explain_metrics

    return ["why (the plant's structure, at this design; `fte tune` searches for a design that does better): " + s
            for s in explain_metrics(d, m)]  # fmt: skip


@main.command()
@click.argument("target", metavar="DESIGN.json|PLANT")
@click.option(
    "--paths", type=int, help="Brownian paths (default: the scenario's, the paper's for built-ins)."
)
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the random generator.")
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
@click.option("--scheduler", help="Address of a dask.distributed scheduler: run the paths on its workers.")
@click.option("--fast-math", "fast_math", is_flag=True,
              help="Fast mode: fused multiply-adds and a vector math library (equal to the default within "
                   "the tolerance of docs/simulation.md; the same numbers for any split of the paths).")  # fmt: skip
@click.option("--measurement-noise", "noise",
              help="Standard deviations of white noise on the outputs, one per output (e.g. 0.01,0,0.02), in the "
                   "outputs' units; overrides the scenario's.")  # fmt: skip
@click.option("--false-alarm-rate", "fa_rate", type=float,
              help="False alarms per unit of the plant's time the detection thresholds are set for "
                   "(default: one per hour of operation).")  # fmt: skip
@click.option("--accommodate", is_flag=True,
              help="Compensate a fault in the control only while it is detected and isolated (thresholds calibrated "
                   "on fault-free paths at --false-alarm-rate); the C and FMU of --save-design's document do the same.")  # fmt: skip
@click.option("--release", "release", type=float, default=0.5, show_default=True,
              help="With --accommodate: a compensated fault stays compensated until |fhat| / threshold falls below "
                   "this ratio (hysteresis); 1: the memoryless gate.")  # fmt: skip
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
def simulate(target, paths, seed, dt, plots, save, scheduler, fast_math, noise, fa_rate, accommodate, release,
             save_design, no_detect, as_json, quiet, plant_opt, allow_uncertified):  # fmt: skip
    """Monte Carlo of the closed loop on the nonlinear stochastic plant: per path fault-free,
    faulty without tolerant control, faulty with it."""
    from .plants.loader import load_plant, load_scenario
    from .resources import check_paths_memory
    from .sim import save_result
    from .sim import simulate as run_sim

    if paths is not None and paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")
    _check_seed(seed)
    if dt is not None:
        _positive("dt", dt)
    if save:
        _writable_target(save, "--save", "result.npz")
    _outputs(save, plots, save_design)
    d, spec = _design_or_plant(
        target, progress=not quiet, plant=plant_opt, allow_uncertified=allow_uncertified
    )
    spec = _need_plant(d, spec, "simulate")
    plant = load_plant(spec)
    scenario = _with_noise(load_scenario(spec), noise)
    check_paths_memory(d, scenario, paths or scenario.paths, dt, bool(save))
    if not (0 < release <= 1):
        raise ParameterError(f"--release must be in (0, 1] (1: no hysteresis); got {release}")
    if save_design and not accommodate:
        raise ParameterError(
            "--save-design writes the design with its accommodation thresholds: give --accommodate"
        )
    if save_design:
        _writable_target(save_design, "--save-design", "design.json")
    if accommodate:
        from .sim.accommodate import accommodated

        d = accommodated(
            d,
            plant,
            scenario,
            paths=paths or scenario.paths,
            seed=seed,
            false_alarm_rate=fa_rate,
            dt=dt,
            release=release,
        )
        click.echo(f"note: {d.status[-1]}", err=True)
        if save_design:
            d.save(save_design)
            click.echo(f"design with accommodation written to {save_design}", err=True)
    res = run_sim(d, plant, scenario, paths=paths or scenario.paths, seed=seed, dt=dt, progress=not quiet,
                  record_all=bool(save), scheduler=scheduler, exact=not fast_math, detect=not no_detect,
                  false_alarm_rate=fa_rate)  # fmt: skip
    m = res.metrics
    if save:
        save_result(res, save)
    figs = []
    if plots:
        from .plot import write_figures

        figs = write_figures(res, plots)
    warn = _warnings(m, list(plant.input_names), list(plant.fault_names), list(plant.output_names),
                     list(plant.output_units))  # fmt: skip
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
    if save:
        click.echo(f"per-path arrays of all {res.paths} paths written to {save}", err=True)
    if figs:
        click.echo(
            f"{len(figs)} figures written to {plots} (over the first {res.recorded_paths} paths)", err=True
        )


# -- sweep --------------------------------------------------------------------------------
@main.command()
@click.argument("target", metavar="DESIGN.json|PLANT")
@click.option("--vary", "vary", multiple=True, required=True,
              help="NAME=V1,V2,... with NAME one of fault_scale, noise_scale, d_scale, measurement_noise_scale; "
                   "repeat for a grid.")  # fmt: skip
@click.option("--paths", type=int, help="Brownian paths per point (default: the scenario's).")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed of the random generator.")
@click.option("--scheduler", help="Address of a dask.distributed scheduler: run the paths on its workers.")
@click.option("--fast-math", "fast_math", is_flag=True,
              help="Fast mode: fused multiply-adds and a vector math library (equal to the default within "
                   "the tolerance of docs/simulation.md; the same numbers for any split of the paths).")  # fmt: skip
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
    from .atomic import atomic_write_text
    from .plants.loader import load_plant, load_scenario
    from .resources import check_paths_memory
    from .sim.sweep import parse_vary, to_csv, to_json
    from .sim.sweep import sweep as run_sweep

    grid = parse_vary(vary)
    _outputs(out_dir)
    if paths is not None and paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")
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
        from .plot import sweep_figure

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
        for w in _warnings(
            p["metrics"], list(plant.input_names), list(plant.fault_names), list(plant.output_names)
        ):
            click.echo(textwrap.fill(f"fte: at {at}: {w}", width=100), err=True)


# -- reproduce ----------------------------------------------------------------------------
@main.command()
@click.argument(
    "which", type=click.Choice(["manipulator", "three-tank", "quadruple-tank", "all"]), default="all"
)
@click.option("--out", "out_dir", default="fte-report", show_default=True, type=click.Path(file_okay=False))
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--paths", type=int, help="At least this many paths (default: the paper's counts).")
@_guard
def reproduce(which, out_dir, seed, paths):
    """The main job: the paper's examples end to end, and a Markdown report with tables and figures."""
    from .report import reproduce as run

    _check_seed(seed)
    if paths is not None and paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        click.echo(f"{time.perf_counter() - t0:7.1f} s  {msg}", err=True)

    _outputs(out_dir)
    report = run(which, out_dir, seed=seed, paths=paths, log=log)
    click.echo(f"report written to {report} ({time.perf_counter() - t0:.1f} s)")


# -- bench --------------------------------------------------------------------------------
#: the parts of `fte bench` (fte_casadi.bench.PARTS; repeated here so that `fte --help` imports no benchmark)
BENCH_PARTS = ("design", "growth", "monte-carlo", "c-step")


@main.command()
@click.option("--json", "as_json", is_flag=True, help="Print all figures as JSON on stdout.")
@click.option(
    "--paths", type=int, default=1000, show_default=True, help="Monte Carlo paths of the engine run."
)
@click.option(
    "--only", type=click.Choice(BENCH_PARTS), multiple=True,
    help="Run only this part (repeatable; default: all of them).",
)  # fmt: skip
@_guard
def bench(as_json, paths, only):
    """Speed of design, Monte Carlo and the C step, against baselines run in the same process."""
    if paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")
    from .bench import run_all, summary_lines

    out = run_all(paths, log=lambda msg: click.echo(msg, err=True), only=only)
    if as_json:
        click.echo(json.dumps(out, indent=1, default=str))
        return
    click.echo("\n".join(summary_lines(out)))


# -- tune ---------------------------------------------------------------------------------
#: what fte tune writes in DIR (and keeps in DIR.partial while it runs); DIR is replaced as a whole
_TUNE_ENTRIES = ("tuned.json", "tune.json", "pareto.png", "designs", "optuna.db")


def _tune_dirs(out_dir: str) -> tuple[Path, Path]:
    """DIR and the folder beside it where a run keeps its trials (optuna.db) and writes the new set."""
    out = Path(out_dir)
    here = Path.cwd().resolve()
    if out.resolve() in (here, *here.parents):
        raise ParameterError(f"--out {out_dir} is the current directory or above it; fte tune replaces its --out "
                             "directory as a whole: give a directory of its own, such as fte-tune")  # fmt: skip
    return out, out.parent / f"{out.resolve().name}.partial"


def _is_optuna_db(path: Path) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(16) == b"SQLite format 3\x00"
    except OSError:
        return False


def _tune_folder(folder: Path, option: str) -> None:
    """Refuse, before any work, a folder holding anything fte tune did not write: it is replaced as a whole."""
    from .tune.output import is_tune_record

    if folder.exists() and not folder.is_dir():
        raise ParameterError(f"{option} {folder} is a file; give a directory (fte tune writes tuned.json and more "
                             "there)")  # fmt: skip
    if not folder.is_dir():
        return
    _writable_target(str(folder / "tuned.json"), option, "design.json")
    rec, fig, designs = folder / "tune.json", folder / "pareto.png", folder / "designs"
    if rec.exists() and not is_tune_record(rec):
        raise ParameterError(f"{rec} exists and was not written by fte tune: it is left untouched; choose another "
                             "--out directory, or move that file away first")  # fmt: skip
    if fig.exists() and not rec.exists():
        raise ParameterError(f"{fig} exists and the directory holds no tune.json of fte tune: it is left untouched; "
                             "choose another --out directory, or move that file away first")  # fmt: skip
    if designs.exists() and not designs.is_dir():
        raise ParameterError(
            f"{designs} is a file; fte tune writes the front's designs into that folder: move it away"
        )
    # left by a kill while a file was written (and optuna.db-journal by SQLite)
    temp = re.compile(r"^\..+\.tmp$")
    for f in designs.iterdir() if designs.is_dir() else ():
        if not (re.fullmatch(r"trial-\d+\.json", f.name) and _ours(f)) and not temp.match(f.name):
            raise ParameterError(f"{f} exists and was not written by fte (it is not a design document): it is left "
                                 "untouched; choose another --out directory, or move that file away first")  # fmt: skip
    for f in folder.iterdir():
        ours = (
            _is_optuna_db(f)
            if f.name == "optuna.db"
            else f.name in _TUNE_ENTRIES or f.name.startswith("optuna.db-") or bool(temp.match(f.name))
        )
        if not ours:
            raise ParameterError(f"{f} was not written by fte tune, which replaces {folder} as a whole: it is left "
                                 "untouched; choose another --out directory, or move it away first")  # fmt: skip


def _tune_target(out_dir: str, resume: bool = False) -> tuple[Path, Path]:
    """Check DIR and DIR.partial before any work; return them."""
    out, work = _tune_dirs(out_dir)
    _tune_folder(out, "--out")
    _tune_folder(work, "the folder of an interrupted run")
    if (work / "optuna.db").exists() and not resume:
        raise ParameterError(f"{work} holds the trials of an interrupted fte tune run (optuna.db): continue it with "
                             f"--resume, or remove {work} to start afresh")  # fmt: skip
    return out, work


def _tune_work(out: Path, work: Path, resume: bool) -> str:
    """Make DIR.partial ready for the run (with --resume of a finished run, a copy of its trials);
    return the optuna storage of the run."""
    import shutil

    kept = work / "optuna.db"
    if work.is_dir() and not kept.exists():  # an earlier run stopped before its first trial was kept
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    if resume and not kept.exists() and _is_optuna_db(out / "optuna.db"):  # a finished run, continued
        shutil.copyfile(out / "optuna.db", kept)
    return f"sqlite:///{kept.resolve()}"


@main.command()
@click.argument("target", metavar="PLANT|DESIGN.json")
@click.option(
    "--trials",
    type=int,
    default=60,
    show_default=True,
    help="Trials in all, trial 0 (the base design) included.",
)
@click.option(
    "--seed", type=int, default=0, show_default=True, help="Seed of the sampler and of the Monte Carlo."
)
@click.option("--objective", "rule", default="balanced", show_default=True,
              help="How the chosen design is picked from the front: balanced, fault-error, false-alarm, ftc or bound.")  # fmt: skip
@click.option(
    "--paths", type=int, help="Brownian paths per candidate (default: 20, or the scenario's when more)."
)
@click.option(
    "--scheduler", help="Address of a dask.distributed scheduler: run the candidates on its workers."
)
@click.option("--out", "out_dir", default="fte-tune", show_default=True, type=click.Path(file_okay=False),
              help="Directory of tuned.json, tune.json, pareto.png and designs/.")  # fmt: skip
@click.option(
    "--json", "as_json", is_flag=True, help="Print the front (JSON list) on stdout; the tables go to stderr."
)
@click.option("--resume", is_flag=True,
              help="Continue the run kept in DIR.partial (interrupted) or DIR (finished, for more --trials).")  # fmt: skip
@click.option("--quiet", is_flag=True, help="No progress bar.")
@_plant_option
@_guard
def tune(target, trials, seed, rule, paths, scheduler, out_dir, as_json, quiet, plant_opt, resume):
    """Multi-objective search over the design's knobs (gamma, gamma1, sigma, alpha, kappa, sliding gain,
    boundary layer): each candidate designed, certified and simulated with the same random numbers;
    the Pareto front, and the chosen design in DIR/tuned.json (see docs/tune.md for the rule)."""
    import shutil

    from .errors import MissingDependencyError
    from .plants.loader import load_plant, load_scenario
    from .tune.output import comparison, dominates, fmt_rows, front_documents, front_table, write_outputs
    from .tune.search import RULES
    from .tune.search import tune as run_tune

    if trials < 2:
        raise ParameterError(f"--trials must be at least 2 (trial 0 is the base design, the others the search); "
                             f"got {trials}")  # fmt: skip
    _check_seed(seed)
    if rule not in RULES:
        raise ParameterError(f"unknown --objective {rule!r}: choose one of {', '.join(RULES)} (docs/tune.md says "
                             "what each picks)")  # fmt: skip
    if paths is not None and paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")
    try:
        import optuna  # noqa: F401
    except ImportError:
        raise MissingDependencyError("fte tune needs optuna: pip install 'fte_casadi[tune]'") from None
    out, work = _tune_target(out_dir, resume)
    _outputs(out, work)
    given = target.endswith(".json") or Path(target).is_file()
    d, spec = _design_or_plant(target, progress=not quiet, plant=plant_opt)
    spec = _need_plant(d, spec, "tune")
    plant = load_plant(spec)
    try:
        scenario = load_scenario(spec)
    except FteError as exc:
        raise ParameterError(f"fte tune simulates every candidate on the plant's scenario, and {d.plant_spec} has "
                             f"none ({exc}); add a scenario() beside the plant function") from None  # fmt: skip
    done = [0]  # trials finished and kept, for the message after a Ctrl-C

    def progress(k: int, n: int) -> None:
        done[0] = k
        bar.update(k - bar.n)

    click.get_current_context().meta["fte.on_interrupt"] = lambda: (
        f"the finished trials ({done[0]}) are kept in {work / 'optuna.db'} and {out} is as it was: run the same "
        "command with --resume to continue" if (work / "optuna.db").exists() else f"{out} is as it was")  # fmt: skip
    with tqdm(total=trials, desc=f"tune {plant.name}", unit=" trials", file=sys.stderr, disable=quiet,
              delay=1.0) as bar:  # fmt: skip
        storage = _tune_work(out, work, resume)
        try:
            result = run_tune(d, plant, scenario, trials=trials, seed=seed, rule=rule, paths=paths,
                              scheduler=scheduler, base_is_given=given, progress=progress, storage=storage,
                              resume=resume)  # fmt: skip
        finally:
            if not (work / "optuna.db").exists():  # stopped before a trial was kept: nothing to resume
                shutil.rmtree(work, ignore_errors=True)
    try:
        files = write_outputs(result, out_dir, work=work)
    except FteError as exc:
        raise ParameterError(f"{exc}; the trials are kept in {work / 'optuna.db'}: run the same command with "
                             "--resume to write them") from None  # fmt: skip
    say = functools.partial(click.echo, err=as_json)
    failed = [r for r in result.records if r.state != "ok"]
    say(f"{plant.name}: {len(result.records)} trials ({len(failed)} failed: not designed or not certified), "
        f"{result.paths} paths each, seed {seed}, {result.wall_s:.1f} s; Pareto front of {len(result.front)} over "
        f"{len(result.objectives)} objectives (* chosen by rule {rule}, d the base design):")  # fmt: skip
    for line in front_table(result):
        say("  " + line)
    rows = comparison(result.baseline.metrics, result.record(result.chosen).metrics, list(plant.fault_names),
                      list(plant.input_names))  # fmt: skip
    say(f"default (trial 0) vs chosen (trial {result.chosen}; {result.tier}):")
    for line in fmt_rows(rows):
        say("  " + line)
    say("  the chosen design is " + ("at least as good as the default on every fault metric" if dominates(rows)
        else "NOT better than the default on every fault metric (a trade-off: see the rows marked worse)"))  # fmt: skip
    reasons: dict[str, int] = {}
    for r in failed:
        key = re.sub(r"-?\d+\.\d+(e[-+]?\d+)?|\d+e[-+]?\d+", "#", ":".join((r.reason or "").split(":")[:2]))[
            :110
        ]
        reasons[key] = reasons.get(key, 0) + 1
    for why, k in sorted(reasons.items(), key=lambda t: -t[1]):
        say(f"  failed trials: {k} x {why}")
    for line in result.limits:
        click.echo(textwrap.fill("fte: " + line, width=100), err=True)
    say(f"wrote {files['tuned']} (the chosen design), {files['record']}, {files['figure']} and the front's designs in "
        f"{files['designs']}")  # fmt: skip
    if as_json:
        click.echo(json.dumps(front_documents(result, out_dir), indent=1))
