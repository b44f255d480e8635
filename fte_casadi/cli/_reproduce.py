"""``fte reproduce``: the paper's examples end to end, and the report."""

from __future__ import annotations

import time

import click

from ._common import _check_paths, _check_seed, _guard, _outputs


@click.command()
@click.argument(
    "which", type=click.Choice(["manipulator", "three-tank", "quadruple-tank", "all"]), default="all"
)
@click.option("--out", "out_dir", default="fte-report", show_default=True, type=click.Path(file_okay=False))
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--paths", type=int, help="At least this many paths (default: the paper's counts).")
@_guard
def reproduce(which, out_dir, seed, paths):
    """The main job: the paper's examples end to end, and a Markdown report with tables and figures."""
    from .._report import reproduce as run

    _check_seed(seed)
    _check_paths(paths)
    t0 = time.perf_counter()

    def log(msg: str) -> None:
        click.echo(f"{time.perf_counter() - t0:7.1f} s  {msg}", err=True)

    _outputs(out_dir)
    report = run(which, out_dir, seed=seed, paths=paths, log=log)
    click.echo(f"report written to {report} ({time.perf_counter() - t0:.1f} s)")
