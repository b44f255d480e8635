"""The ``fte`` command: the only place that prints or exits.

Every command turns the library's errors into a one-paragraph message and exit status 2
(bad input) or 1 (a failed design/run); ``--debug`` shows the Python traceback instead.
"""

from __future__ import annotations

import functools
import json
import sys
import textwrap

import click
import numpy as np

from .errors import FteError, InfeasibleDesignError, ParameterError

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> None:
    click.echo(textwrap.fill("fte: " + " ".join(message.split()), width=100), err=True)
    sys.exit(code)


def _guard(fn):
    """Run a command; on a known error print one paragraph and exit non-zero."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        debug = click.get_current_context().find_root().params.get("debug", False)
        try:
            return fn(*args, **kwargs)
        except InfeasibleDesignError as exc:
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
            _fail("interrupted; nothing was written", 130)
        except Exception as exc:  # noqa: BLE001 - the last line of defence: no traceback for users
            if debug:
                raise
            _fail(
                f"internal error {type(exc).__name__}: {exc}. This is a bug in fte_casadi or an unexpected "
                "input; run again with `fte --debug ...` to see where, and report it",
                3,
            )

    return wrapper


def _positive(name: str, value, allow_zero: bool = False):
    if value is None:
        return None
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        raise ParameterError(f"--{name} must be a positive finite number; got {value}")
    return value


@click.group(context_settings={"help_option_names": ["-h", "--help"]})
@click.option("--debug", is_flag=True, help="Show Python tracebacks on errors.")
@click.version_option(package_name="fte_casadi")
def main(debug: bool) -> None:
    """fte: certified fault estimation and fault-tolerant control, from CasADi equations to embedded C.

    PLANT is a built-in name (manipulator, three-tank), path/to/file.py:function or
    package.module:function returning a Plant.
    """


# -- derive -------------------------------------------------------------------------------
def _fmt_matrix(M: np.ndarray, indent: str = "    ") -> str:
    M = np.atleast_2d(M)
    if M.size == 0:
        return indent + "[]"
    rows = [" ".join(f"{v:>10.5g}" for v in row) for row in M]
    return "\n".join(indent + r for r in rows)


@main.command()
@click.argument("plant")
@click.option("--json", "as_json", is_flag=True, help="Print the derive document (JSON) on stdout.")
@_guard
def derive(plant: str, as_json: bool) -> None:
    """Derive the T-S fuzzy model of PLANT and check its fidelity."""
    from .plants.loader import load_plant
    from .ts import derive as derive_ts

    p = load_plant(plant)
    ts = derive_ts(p)
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
    )
