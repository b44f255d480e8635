"""``fte design``: the observer and tolerant controller by LMIs, or the feasible frontier (--explore)."""

from __future__ import annotations

import sys
import textwrap
from pathlib import Path

import click
from tqdm import tqdm

from ..errors import InfeasibleDesignError, ParameterError
from ._common import _guard, _outputs, _positive, _writable_target
from ._targets import _VERTICES, _design_options, _make_design, _scenario


def _gamma_min_text(g) -> str:
    """The frontier's gamma_min: '-' where no gamma makes (45) feasible, 'any' without unknown inputs (0)."""
    return "-" if g is None else ("any" if g == 0 else format(g, ".4g"))


def _check_params(**kw) -> dict:
    """The options given, each positive (alpha, d_bound, bound_weight: >= 0) and at most
    :data:`~fte_casadi.design._docchecks.PARAM_MAX`, before any work."""
    from ..design import param_problem

    out = {}
    for k, v in kw.items():
        if v is not None:
            _positive(k, v, allow_zero=(k in ("alpha", "beta", "d_bound", "bound_weight", "settle_window")))
            why = param_problem(v)
            if why:
                raise ParameterError(f"--{k.replace('_', '-')} {why}")
            out[k] = v
    return out


def _save(d, output: str) -> None:
    """Write the design document to ``output``: a MAT file when it ends in .mat, else JSON."""
    if Path(output).suffix.lower() == ".mat":
        d.save_mat(output)
        click.echo(f"design document written to {output} (MAT file: every matrix under its contract name)")
    else:
        d.save(output)
        click.echo(f"design document written to {output}")


def _explore(plant_spec: str, options, vertices: str | None, out_dir: str, output: str | None = None,
             always_compensate: bool = False) -> None:  # fmt: skip
    """The feasible frontier of ``plant_spec`` with the options of a design (``options``: every option of
    ``fte design`` but gamma, sigma and --allow-uncertified, which :func:`~fte_casadi.design.explore` refuses); the
    best design written with ``output`` gets the gate ``fte design`` gives (:func:`fte_casadi.sim.protected`)."""
    from ..design import explore
    from ..plants import load_plant
    from ..plot import frontier_figure
    from ..ts import derive as derive_ts

    ts = derive_ts(load_plant(plant_spec), vertices=vertices)
    with tqdm(total=12, desc=f"explore {ts.plant.name}", unit=" sigma", file=sys.stderr, delay=1.0) as bar:
        points, info = explore(ts, options, progress=lambda k, n: bar.update(1))
    click.echo(
        f"feasible frontier of {ts.plant.name} (gamma1 = {info['gamma1']:g}; (45) is feasible for any gamma only with "
        f"sigma < {info['sigma_sup']:.4g}); the plant's defaults: gamma = {info['gamma']:g}, sigma = {info['sigma']:g}"
    )
    click.echo(
        f"{'sigma':>10} {'gamma_min (45)':>15} {'certified from':>15} {'alpha':>9} {'max|L1|':>9} {'ts_max':>9}"
    )
    for pt in points:
        click.echo(
            f"{pt.sigma:10.4g} {_gamma_min_text(pt.gamma_min):>15} "
            f"{'-' if pt.gamma_tried is None else format(pt.gamma_tried, 'g'):>15} "
            f"{'-' if pt.alpha is None else format(pt.alpha, '.3g'):>9} "
            f"{'-' if pt.max_abs_L1 is None else format(pt.max_abs_L1, '.3g'):>9} "
            f"{'-' if pt.ts_max is None else format(pt.ts_max, '.3g'):>9}"
            + (f"  {pt.note}" if pt.note and not pt.certified else "")
        )
    fig = frontier_figure(points, info, ts.plant.name, out_dir)
    click.echo(f"figure written to {fig}")
    if info["skipped"]:
        click.echo(f"{info['skipped']} of the sigmas were not tried: the time budget (60 s) ran out")
    best = info["best"]
    if best is None:  # no certified design exists on the frontier: exit 1, as a refused design
        raise InfeasibleDesignError(
            "--explore found no certified design"
            + (f": {info['cause']}" if info["cause"] else "")
            + " (the frontier above lists what each sigma gave)"
        )
    click.echo(
        f"best certified design found ({info.get('best_from') or 'the fastest observer'}): sigma = "
        f"{best.params.sigma:.4g}, gamma = {best.params.gamma:g}, decay rate {best.observer.alpha:.4g}"
    )
    if output:
        sc = _scenario(plant_spec)
        if (
            sc is not None and not always_compensate
        ):  # as fte design writes it: the gate where the faults cross-talk
            from ..sim import protected

            best = protected(best, ts.plant, sc, paths=sc.paths, seed=0)
        _save(best, output)


@click.command()
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
    "--beta",
    type=float,
    help="the closed loop's decay rate (default: twice the open loop's slowest, or as fast as it diverges, lowered "
    "to what (45) allows; docs/design.md).",
)
@click.option(
    "--settle-within", "settle_window", type=float,
    help="the fault window the observer must settle in, three time constants (default: the scenario's shortest; "
    "0: no requirement); kappa is searched for it.",
)  # fmt: skip
@click.option(
    "--sample-time", "sample_time", type=float,
    help="sample time the observer must run at (default: the plant's scenario step); caps the default alpha.",
)  # fmt: skip
@click.option(
    "--kappa", type=float,
    help="Bound on cond(X') and cond(Pbar) (default 1e4); a larger one allows a faster observer decay rate.",
)  # fmt: skip
@click.option(
    "--bound-weight", "bound_weight", type=float,
    help="Weight of the closed loop's fault-error bound in the observer's objective (default 0: off; 1 counts it "
    "as much as the rest; docs/design.md).",
)  # fmt: skip
@click.option(
    "--always-compensate", "always_compensate", is_flag=True,
    help="Compensate every fault estimate always, as the paper does (default: a fault whose estimate the other "
    "faults' estimates cross-talk into is compensated only while detected and more than they explain).",
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
    "--explore",
    is_flag=True,
    help="Print and plot the feasible frontier (smallest gamma over sigma) within 60 s; with -o, write the best "
    "certified design found.",
)
@_VERTICES
@click.option("--out", "out_dir", type=click.Path(file_okay=False),
              help="With --explore: the directory of the frontier figure (default: fte-explore).")  # fmt: skip
@_guard
def design(plant, variant, solver, gamma, gamma1, sigma, delta, epsilon, alpha, beta, settle_window, sample_time, kappa,
           bound_weight, always_compensate, allow_uncertified, accept, no_remark5, d_bound, output, explore, out_dir,
           vertices):  # fmt: skip
    """Design the observer and tolerant controller of PLANT by LMIs, with certificates."""
    params = _check_params(gamma=gamma, gamma1=gamma1, sigma=sigma, delta=delta, epsilon=epsilon, alpha=alpha,
                           beta=beta, settle_window=settle_window, sample_time=sample_time, d_bound=d_bound,
                           bound_weight=bound_weight, kappa=kappa)  # fmt: skip
    if no_remark5:
        params["remark5"] = False
    if output is not None:
        _writable_target(output, "-o", "design.json")
    if explore:
        refused = [opt for opt, v in (("--gamma", gamma), ("--sigma", sigma)) if v is not None]
        if refused:
            raise ParameterError(
                f"--explore searches gamma and sigma itself: {' and '.join(refused)} cannot be given with it (design "
                "at them without --explore, or leave them out)"
            )
        if allow_uncertified:
            raise ParameterError(
                "--explore writes only a certified design (its best one): --allow-uncertified means nothing with it"
            )
        options = _design_options(plant, variant, solver.upper(), params, False, accept)
        _outputs(out_dir or "fte-explore", output)
        _explore(plant, options, vertices, out_dir or "fte-explore", output,
                 always_compensate=always_compensate or variant == "paper")  # fmt: skip
        return
    if out_dir is not None:
        raise ParameterError(
            f"--out {out_dir} is the directory of --explore's figure; to write the design document use -o FILE"
        )
    _outputs(output)
    d, ts, options = _make_design(plant, variant, solver.upper(), params, allow_uncertified, accept, vertices,
                                  full=True, always_compensate=always_compensate or variant == "paper")  # fmt: skip
    from ..design import design_summary

    click.echo(design_summary(d))
    from ..verdicts import design_warnings

    scenario = _scenario(plant)
    warnings = design_warnings(d.checks, d.observer.alpha, scenario)
    for w in warnings:
        click.echo(textwrap.fill("fte: warning: " + w, width=100), err=True)
    if warnings and d.certified:
        from ..design import remedies

        for line in remedies(ts, options, d, scenario):
            click.echo(textwrap.fill("fte: tried " + line, width=100), err=True)
    if output:
        _save(d, output)
    else:
        click.echo("(design document not saved: add -o FILE)")
