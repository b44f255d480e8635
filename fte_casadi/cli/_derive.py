"""``fte derive``: the T-S model of a plant and its fidelity."""

from __future__ import annotations

import json
import textwrap

import click
import numpy as np

from ._common import _guard
from ._targets import _VERTICES


def _fmt_matrix(M: np.ndarray, indent: str = "    ") -> str:
    M = np.atleast_2d(M)
    if M.size == 0:
        return indent + "[]"
    rows = [" ".join(f"{v:>10.5g}" for v in row) for row in M]
    return "\n".join(indent + r for r in rows)


@click.command()
@click.argument("plant")
@click.option("--json", "as_json", is_flag=True, help="Print the derive document (JSON) on stdout.")
@_VERTICES
@_guard
def derive(plant: str, as_json: bool, vertices: str | None) -> None:
    """Derive the T-S fuzzy model of PLANT and check its fidelity."""
    from ..plants import load_plant
    from ..ts import derive as derive_ts

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
    from ..design import missed_motion

    if (missed := missed_motion(ts)) is not None:  # the model about x = 0 misses the motion at the reference
        click.echo(textwrap.fill("fte: " + missed[1], width=100), err=True)
