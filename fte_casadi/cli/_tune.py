"""``fte tune``: the multi-objective search over the design's knobs, its front and the chosen design."""

from __future__ import annotations

import functools
import json
import re
import sys
import textwrap
from pathlib import Path

import click
from tqdm import tqdm

from .._text import shorten
from ..errors import FteError, ParameterError
from ._common import _check_paths, _check_seed, _guard, _ours, _outputs, _writable_target
from ._targets import _design_or_plant, _need_plant, _plant_option

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
    from ..tune import is_tune_record

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


def _tune_work(out: Path, work: Path, resume: bool) -> tuple[str, bool]:
    """Make DIR.partial ready for the run (with --resume of a finished run, a copy of its trials);
    return the optuna storage of the run and whether its trials are that copy."""
    import shutil

    kept = work / "optuna.db"
    if work.is_dir() and not kept.exists():  # an earlier run stopped before its first trial was kept
        shutil.rmtree(work)
    work.mkdir(parents=True, exist_ok=True)
    copied = resume and not kept.exists() and _is_optuna_db(out / "optuna.db")
    if copied:  # a finished run, continued
        shutil.copyfile(out / "optuna.db", kept)
    return f"sqlite:///{kept.resolve()}", copied


def _trial_count(db: Path) -> int:
    """The trials an optuna database holds (0 when it holds no search)."""
    import optuna

    try:
        return sum(s.n_trials for s in optuna.get_all_study_summaries(storage=f"sqlite:///{db.resolve()}"))
    except Exception:  # noqa: BLE001 - an unreadable database holds nothing to keep
        return 0


def _tune_options(trials, seed, rule, paths, scheduler, given, progress, storage, resume):
    """The one place ``fte tune``'s flags become the search's :class:`~fte_casadi.tune.TuneOptions` (``progress``
    and ``storage``: the bar's update and the run's optuna database in DIR.partial)."""
    from ..tune import TuneOptions

    return TuneOptions(trials=trials, seed=seed, rule=rule, paths=paths, scheduler=scheduler, base_is_given=given,
                       progress=progress, storage=storage, resume=resume)  # fmt: skip


@click.command()
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

    from ..plants import load_plant, load_scenario
    from ..tune import front_documents, write_outputs
    from ..tune import tune as run_tune

    _check_tune_flags(trials, seed, rule, paths)
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
        storage, copied = _tune_work(out, work, resume)
        try:
            opts = _tune_options(trials, seed, rule, paths, scheduler, given, progress, storage, resume)
            result = run_tune(d, plant, scenario, options=opts)
        except BaseException:
            # a refused --resume of a finished run (another --seed, target or --paths) leaves no copy of its
            # trials behind, which the next run would take for an interrupted one
            if copied and _trial_count(work / "optuna.db") <= _trial_count(out / "optuna.db"):
                shutil.rmtree(work, ignore_errors=True)
            raise
        finally:
            if not (work / "optuna.db").exists():  # stopped before a trial was kept: nothing to resume
                shutil.rmtree(work, ignore_errors=True)
    try:
        files = write_outputs(result, out_dir, work=work)
    except FteError as exc:
        raise ParameterError(f"{exc}; the trials are kept in {work / 'optuna.db'}: run the same command with "
                             "--resume to write them") from None  # fmt: skip
    _say_tune(result, plant, seed, rule, files, as_json)
    if as_json:
        click.echo(json.dumps(front_documents(result, out_dir), indent=1))


def _check_tune_flags(trials, seed, rule, paths) -> None:
    """Refuse, before any work, out-of-range flags and a missing optuna."""
    from ..errors import MissingDependencyError
    from ..tune import RULES

    if trials < 2:
        raise ParameterError(f"--trials must be at least 2 (trial 0 is the base design, the others the search); "
                             f"got {trials}")  # fmt: skip
    _check_seed(seed)
    if rule not in RULES:
        raise ParameterError(f"unknown --objective {rule!r}: choose one of {', '.join(RULES)} (docs/tune.md says "
                             "what each picks)")  # fmt: skip
    _check_paths(paths)
    try:
        import optuna  # noqa: F401
    except ImportError:
        raise MissingDependencyError("fte tune needs optuna: pip install 'fte_casadi[tune]'") from None


def _say_tune(result, plant, seed: int, rule: str, files: dict, as_json: bool) -> None:
    """The front, the default against the chosen design, the failed trials by reason, the limits and the files
    written (on stderr with --json)."""
    from ..tune import comparison, dominates, fmt_rows, front_table

    say = functools.partial(click.echo, err=as_json)
    failed = [r for r in result.records if r.state != "ok"]
    say(f"{plant.name}: {len(result.records)} trials ({len(failed)} failed: not designed or not certified), "
        f"{result.paths} paths each, seed {seed}, {result.wall_s:.1f} s; Pareto front of {len(result.front)} over "
        f"{len(result.objectives)} objectives (* chosen by rule {rule}, d the base design):")  # fmt: skip
    for line in front_table(result):
        say("  " + line)
    rows = comparison(result.baseline.metrics, result.record(result.chosen).metrics, list(plant.fault_names),
                      list(plant.input_names), list(plant.output_names))  # fmt: skip
    say(f"default (trial 0) vs chosen (trial {result.chosen}; {result.tier}):")
    for line in fmt_rows(rows):
        say("  " + line)
    say("  the chosen design is " + ("at least as good as the default on every fault metric" if dominates(rows)
        else "NOT better than the default on every fault metric (a trade-off: see the rows marked worse)"))  # fmt: skip
    reasons: dict[str, int] = {}
    for r in failed:
        key = shorten(
            re.sub(r"-?\d+\.\d+(e[-+]?\d+)?|\d+e[-+]?\d+", "#", ":".join((r.reason or "").split(":")[:2])),
            110,
        )
        reasons[key] = reasons.get(key, 0) + 1
    for why, k in sorted(reasons.items(), key=lambda t: -t[1]):
        say(f"  failed trials: {k} x {why}")
    for line in result.limits:
        click.echo(textwrap.fill("fte: " + line, width=100), err=True)
    say(f"wrote {files['tuned']} (the chosen design), {files['record']}, {files['figure']} and the front's designs in "
        f"{files['designs']}")  # fmt: skip
