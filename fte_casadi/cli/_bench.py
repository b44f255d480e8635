"""``fte bench``: the speed of design, Monte Carlo and the C step, against baselines."""

from __future__ import annotations

import json

import click

from ..errors import ParameterError
from ._common import _check_paths, _guard


def _weights(listed: str | None) -> list[float]:
    """--weights: numbers >= 0, separated by commas."""
    if listed is None:
        raise ParameterError("--bound-weights needs the weights: --weights W1,W2,... (e.g. 0,0.3,1,3,10)")
    try:
        out = [float(w) for w in listed.split(",")]
    except ValueError:
        out = []
    if not out or not all(w >= 0 for w in out):
        raise ParameterError(
            f"--weights {listed!r}: give weights >= 0 separated by commas, e.g. 0,0.3,1,3,10"
        )
    return out


def _params(text: str | None) -> dict | None:
    """--at: a JSON object of numbers, or a message naming what is wrong."""
    if text is None:
        return None
    try:
        out = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ParameterError(
            f"--at {text!r} is not JSON ({exc.msg}); give an object, e.g. '{{\"sigma\": 0.35}}'"
        ) from None
    if not isinstance(out, dict) or not all(isinstance(v, (int, float)) for v in out.values()):
        raise ParameterError(f"--at {text!r}: give a JSON object of numbers, e.g. '{{\"sigma\": 0.35}}'")
    return out


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
@click.option(
    "--diffusion", "diffusion_plant", metavar="PLANT",
    help="Instead of the speed: for PLANT, the largest scale of its diffusion each condition allows, from the "
    "design's certificate down to what no controller can beat (JSON on stdout; docs/design.md).",
)  # fmt: skip
@click.option(
    "--bound-weights", "weights_plant", metavar="PLANT",
    help="Instead of the speed: the built-in PLANT designed at each of --weights (the fault-error bound's weight in "
    "step 5's objective), its bound and its Monte Carlo figures on --paths paths (one JSON line per weight).",
)  # fmt: skip
@click.option("--weights", metavar="W1,W2,...", help="With --bound-weights: the weights, e.g. 0,0.3,1,3,10.")
@click.option(
    "--at", "at_params", metavar="JSON",
    help="With --diffusion: the design parameters; with --bound-weights: the plant's design defaults replaced "
    "(a JSON object of numbers, e.g. '{\"sigma\": 0.35}').",
)  # fmt: skip
@_guard
def bench(as_json, paths, only, diffusion_plant, weights_plant, weights, at_params):
    """Speed of design, Monte Carlo and the C step, against baselines run in the same process."""
    if diffusion_plant is not None:
        from ..bench import diffusion_scales

        out = diffusion_scales(diffusion_plant, _params(at_params), log=lambda msg: click.echo(msg, err=True))
        click.echo(json.dumps(out))
        return
    if weights_plant is not None:
        from ..bench import bound_weight_rows
        from ..plants import BUILTIN

        if weights_plant not in BUILTIN:
            raise ParameterError(
                f"--bound-weights {weights_plant!r}: give a built-in plant ({', '.join(BUILTIN)})"
            )
        _check_paths(paths)
        bound_weight_rows(weights_plant, _weights(weights), paths, defaults=_params(at_params),
            on_row=lambda row: click.echo(json.dumps(row)))  # fmt: skip
        return
    if at_params is not None or weights is not None:
        raise ParameterError(
            "--at and --weights go with --diffusion PLANT or --bound-weights PLANT; give one"
        )
    _check_paths(paths)
    from ..bench import run_all, summary_lines

    out = run_all(paths, log=lambda msg: click.echo(msg, err=True), only=only)
    if as_json:
        click.echo(json.dumps(out, indent=1, default=str))
        return
    click.echo("\n".join(summary_lines(out)))
