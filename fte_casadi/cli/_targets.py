"""What a command works on: a design document, checked before use, or a plant designed on the fly;
the plant's scenario; and the options that name them."""

from __future__ import annotations

import contextlib
import shutil
import sys
import textwrap
import time
from pathlib import Path

import click
from tqdm import tqdm

from .._progress import note, reporting
from ..errors import ParameterError

#: seconds a design runs before its status line shows
STATUS_DELAY = 1.0

_VERTICES = click.option(
    "--vertices", type=click.Choice(["grouped", "box", "fewest"]), default=None,
    help="How the premises of a sector model are covered: grouped (premises that depend on the same states "
    "together, a simplex or a box per group, whichever has fewer vertices; the default for premises found "
    "automatically), box (each premise its own sector: 2^q rules, the most vertices; the default for declared "
    "premises), fewest (one simplex over all premises: q + 1 rules, the loosest).",
)  # fmt: skip


def _scenario(plant_spec: str):
    """The plant's scenario, or None when it has none."""
    from ..errors import PlantLoadError
    from ..plants import load_scenario

    try:
        return load_scenario(plant_spec)
    except PlantLoadError:
        return None


def _absolute_spec(plant_spec: str) -> str:
    """A ``file.py:function`` spec with the file's absolute path, so documents work from any directory."""
    if ":" in plant_spec and plant_spec.rsplit(":", 1)[0].endswith(".py"):
        target, func = plant_spec.rsplit(":", 1)
        return f"{Path(target).resolve()}:{func}"
    return plant_spec


def _design_options(
    plant_spec: str, variant: str, solver: str, params: dict, allow_uncertified: bool = False, accept=()
):  # fmt: skip
    """The options record of a design of ``plant_spec`` on the command line (one record for a design and for
    ``--explore``): the plant as it was named (made absolute), and what its scenario says of the design, unless
    given (:meth:`~fte_casadi.sim.Scenario.design_options`: the sample time, the window the observer settles in,
    the initial state)."""
    from ..design import DesignOptions

    options = DesignOptions(variant=variant, solver=solver, allow_uncertified=allow_uncertified,
                            accept_assumptions=tuple(accept), plant_spec=_absolute_spec(plant_spec), **params)  # fmt: skip
    sc = _scenario(plant_spec)
    if sc is not None:  # its sample time, the window the observer settles in, the C's nominal start
        options = sc.design_options(options)
    return options


@contextlib.contextmanager
def _design_status(name: str, stream=None, clock=time.monotonic):
    """While a design of ``name`` runs: on a terminal (``stream``, default stderr), after :data:`STATUS_DELAY`
    seconds, a status line with the time elapsed and what the design is doing (:mod:`fte_casadi._progress`: the
    step, the parameter search's trial, the diagnosis), each step shown as it starts, cleared when the design ends.
    A refusal's parameter search and diagnosis design again at every value they try, which can take minutes."""
    stream = sys.stderr if stream is None else stream
    # the line is cut to the terminal's width (100 where it reports 0 x 0: tqdm would then show nothing)
    size = shutil.get_terminal_size((100, 24))
    bar = tqdm(total=None, desc=f"design {name}", file=stream, disable=None, ncols=size.columns, nrows=size.lines,
               leave=False, bar_format="{desc} [{elapsed}]{postfix}")  # fmt: skip
    t0 = clock()

    def show(what: str) -> None:
        bar.set_postfix_str(what, refresh=False)
        if clock() - t0 >= STATUS_DELAY:
            bar.refresh()

    try:
        with reporting(show):
            yield
    finally:
        bar.close()


def _make_design(
    plant_spec: str, variant: str, solver: str, params: dict, allow_uncertified: bool = False, accept=(),
    vertices: str | None = None, full: bool = False, always_compensate: bool = False,
):  # fmt: skip
    """The design of ``plant_spec`` for its scenario (:meth:`~fte_casadi.sim.Scenario.design_options`: its sample
    time, fault windows and start, unless given), with the gate that keeps the other faults' estimates out of a
    fault's compensation where they cross-talk (:func:`fte_casadi.sim.protected`; not with ``always_compensate``,
    the paper's policy); with ``full``, ``(design, T-S model, options)``."""
    from ..design import design as run_design
    from ..plants import load_plant
    from ..ts import derive as derive_ts

    options = _design_options(plant_spec, variant, solver, params, allow_uncertified, accept)
    ts = derive_ts(load_plant(plant_spec), vertices=vertices)
    sc = _scenario(plant_spec)
    with _design_status(ts.plant.name):
        d = run_design(ts, options)
        if (
            sc is not None and not always_compensate
        ):  # the other faults' estimates kept out of a fault's compensation
            from ..sim import protected

            note(f"the accommodation gate: calibrated, and measured on {sc.paths} paths of the scenario")
            d = protected(d, ts.plant, sc, paths=sc.paths, seed=0)
    return (d, ts, options) if full else d


def _design_or_plant(
    target: str, progress: bool = True, plant: str | None = None, allow_uncertified: bool = False
):
    """A design document path, or a plant spec designed on the fly (conditioned variant).

    A document is checked before use (:func:`fte_casadi.trust.check_loaded`): re-certified at its numbers,
    against its plant when that is a built-in one or named with ``plant`` (--plant), never running code it
    names. Returns ``(design, plant spec or None)``: the spec of the plant it may be simulated on.
    """
    from ..design import Design
    from ..trust import check_loaded

    p = Path(target)
    if p.is_dir():
        raise ParameterError(f"{target} is a directory; give a design document (the JSON file `fte design PLANT -o "
                             "FILE.json` writes) or a plant (a built-in name, FILE.py:FUNCTION or module:function)")  # fmt: skip
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
