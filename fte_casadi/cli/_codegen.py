"""``fte codegen``: the embedded C of the observer/controller step, and the FMU."""

from __future__ import annotations

import shlex

import click

from ._common import EXIT_FAILED, _fail, _guard, _outputs, _positive
from ._targets import _allow_option, _design_or_plant, _need_plant, _plant_option


@click.command()
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
@click.option(
    "--check", is_flag=True,
    help="Compile the C and feed it the measurements of one simulated path of the plant's scenario (its faulty "
    "run with tolerant control): it must return the inputs and estimates the simulation applied (with --fmu, the "
    "FMU what the C returns). Exit 1 if not.",
)  # fmt: skip
@click.option(
    "--seed", type=click.IntRange(min=0), default=0, show_default=True, help="The simulated path of --check."
)
@_plant_option
@_allow_option
@_guard
def codegen(target, out_dir, sample_time, sample_time_alias, real, boundary_layer, fmu, check, seed, plant_opt,
            allow_uncertified):  # fmt: skip
    """Generate the embedded C of the observer/controller step."""
    from ..codegen import check_fmu_target, default_sample_time, generate_c, generate_c_and_fmu
    from ..plants import SCENARIOS

    if sample_time is not None and sample_time_alias is not None:
        raise click.UsageError("give the sample time once: --sample-time (--ts is its former name)")
    sample_time = sample_time if sample_time_alias is None else sample_time_alias
    _positive("sample-time", sample_time)
    _positive("boundary-layer", boundary_layer)
    _outputs(out_dir)
    if check:  # a compiler, before a design is made
        from ..sim import require_compiler

        require_compiler()
    d, spec = _design_or_plant(target, plant=plant_opt, allow_uncertified=allow_uncertified)
    if check:  # everything else --check needs, before any file is written
        spec = _check_ready(d, spec, boundary_layer)
    if fmu:
        check_fmu_target(d, out_dir)  # a compiler, and no foreign file in the way, before any work
    made_for = default_sample_time(d, SCENARIOS[d.plant]().dt if d.plant in SCENARIOS else None)
    write = generate_c_and_fmu if fmu else generate_c
    files = write(d, out_dir, sample_time=made_for if sample_time is None else sample_time, real=real,
                  boundary_layer=boundary_layer)  # fmt: skip
    how = (
        "--sample-time" if sample_time is not None else "the design's sample time, the step fte simulate runs"
    )
    if sample_time is not None and abs(sample_time - made_for) > 1e-12 * sample_time:
        how += f"; the design was made for {made_for:g}"
    if sample_time is None:
        sample_time = made_for
    c_files = [f for f in files if not f.name.endswith(".fmu")]
    click.echo(f"wrote {len(c_files)} files into {out_dir} as one set: " + ", ".join(f.name for f in c_files))
    click.echo(f"sample time Ts = {sample_time:g} ({how})")
    q = shlex.quote(str(out_dir))
    click.echo(f"compile with: cc -std=c99 -O2 -Wall -Wextra -Werror -pedantic -I{q} {q}/*.c your_main.c -lm")
    for path in files[len(c_files) :]:
        click.echo(f"wrote {path}: FMI 2.0 co-simulation FMU, fixed step Ts = {sample_time:g} (docs/fmu.md)")
    if check:
        _check(d, spec, out_dir, sample_time, real, seed, files[len(c_files)] if fmu else None)


def _check_ready(d, spec, boundary_layer) -> str:
    """The plant spec ``--check`` simulates; a clear error, before any file is written, for what it cannot do."""
    from ..sim import require_same_sliding

    require_same_sliding(d, boundary_layer)
    return _need_plant(d, spec, "codegen --check")


def _check(d, spec, out_dir, sample_time, real, seed, fmu_path=None) -> None:
    from ..plants import load_plant, load_scenario
    from ..sim import check_c

    got = check_c(d, load_plant(spec), load_scenario(spec), out_dir, sample_time=sample_time, real=real, seed=seed,
                  fmu=fmu_path)  # fmt: skip
    if not got.ok:
        _fail(got.render(), EXIT_FAILED)
    click.echo("checked: " + got.render())
