"""``fte bench``: the speed of design, Monte Carlo and the C step, against baselines."""

from __future__ import annotations

import json

import click

from ._common import _check_paths, _guard

#: the parts of `fte bench` (fte_casadi.bench.PARTS; repeated here so that `fte --help` imports no benchmark)
BENCH_PARTS = ("design", "growth", "monte-carlo", "c-step")


@click.command()
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
    _check_paths(paths)
    from ..bench import run_all, summary_lines

    out = run_all(paths, log=lambda msg: click.echo(msg, err=True), only=only)
    if as_json:
        click.echo(json.dumps(out, indent=1, default=str))
        return
    click.echo("\n".join(summary_lines(out)))
