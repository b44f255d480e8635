"""How much a loaded design document is trusted (docs/interface.md, "Trust model").

A document is data. Loading one never runs code it names or holds: its ``plant_spec`` is imported
only when it is a built-in plant's name or when the user names the same plant (``--plant``), and its
scheduling map is rebuilt from that plant, or else replayed from the document's arithmetic tape
(:mod:`fte_casadi.model._tape`), never deserialised. Then the design is re-certified at its own numbers
(:func:`fte_casadi.design._recertify.recertify`), the numbers its step uses beside the certificate are checked
against what they are made of (Kf, H, N, ``checks.ts_max``: :func:`fte_casadi.design._identities.identity_failures`)
and, when the plant is at hand, checked against it: the fingerprint of its equations (``plant_hash``), the local
models of its T-S model, its reference input, input limits, region and initial state; its names are then the
plant's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .design import Design, identity_failures, recertify
from .errors import DesignFileError
from .model import Plant

__all__ = ["Trusted", "plant_for", "with_plant", "check_loaded"]


@dataclass(frozen=True)
class Trusted:
    """A loaded design as it may be used, the plant it was checked against (None: not loaded), the spec
    that plant was loaded from, and what the user should be told (on stderr)."""

    design: Design
    plant: Plant | None
    plant_spec: str | None
    notes: list[str] = field(default_factory=list)


def plant_for(d: Design, given: str | None) -> tuple[Plant | None, str | None]:
    """The plant to check ``d`` against: the one the user named (``given``), else the document's when it is
    a built-in name, else None (a document's ``file.py:function`` or ``module:function`` is not imported on
    the document's word)."""
    from .plants import BUILTIN, load_plant

    if given is not None:
        return load_plant(given), given
    spec = d.plant_spec.strip()
    if spec in BUILTIN:
        return load_plant(spec), spec
    return None, None


def _models_differ(d: Design, ts) -> str:
    """Which matrix of which rule of ``d``'s local models differs from the plant's T-S model ('' if none)."""
    if ts.r != d.r:
        return f"the plant's T-S model has {ts.r} rules, the document {d.r}"
    for i, (a, b) in enumerate(zip(d.local_models, ts.local_models)):
        for k in ("A", "B", "Bd", "Bf", "W", "a", "G", "Gf", "M"):
            x, y = np.asarray(a[k], float), np.asarray(b[k], float)
            if x.shape != y.shape:
                return f"local_models[{i}].{k} is {x.shape}, the plant's {y.shape}"
            scale = max(1.0, float(np.max(np.abs(y))) if y.size else 0.0)
            if x.size and float(np.max(np.abs(x - y))) > 1e-9 * scale:
                return f"local_models[{i}].{k} differs from the plant's by {float(np.max(np.abs(x - y))):.3g}"
    for k in ("C", "Df"):
        if not np.array_equal(np.asarray(getattr(d, k), float), np.asarray(getattr(ts, k), float)):
            return f"{k} differs from the plant's"
    return ""


def with_plant(d: Design, plant: Plant, spec: str | None = None) -> Design:
    """``d`` checked against ``plant`` and with its scheduling map rebuilt from it.

    Raises :class:`DesignFileError` naming what changed when the plant's equations are not those the design
    was made for (its fingerprint, or, for a document without one, its T-S model).
    """
    from .model import PARTS, changed_parts, write_tape
    from .ts import scheduling_from_measurements, structure

    src = d.loaded.get("source", "the design")
    named = f" ({spec})" if spec else ""
    if d.plant_hash:
        changed = changed_parts(d.plant_hash, plant)
        if changed:
            raise DesignFileError(
                f"{src} was designed for another plant: the plant's equations{named} differ from those the design "
                f"was made for, in {', '.join(PARTS[k] for k in changed)}. Design it again for this plant "
                "(`fte design PLANT -o FILE`), or name the plant it was made for with --plant"
            )
    ts = structure(plant, vertices=d.vertices)  # the cover it was designed with (None: the default)
    why = _models_differ(d, ts)
    if why:
        raise DesignFileError(
            f"{src} was designed for another plant: the plant's equations{named} differ from those the design was "
            f"made for ({why}). Design it again for this plant (`fte design PLANT -o FILE`)"
        )
    why = _numbers_differ(d, plant, ts)
    if why:
        raise DesignFileError(
            f"{src} does not match its plant{named}: {why}. Design it again for this plant (`fte design PLANT -o "
            "FILE`), or name the plant it was made for with --plant"
        )
    sched, sources = scheduling_from_measurements(ts)
    names = plant.names(
        sources
    )  # the plant's names, not the document's: names are data, and the plant is the one the user trusts
    return dataclasses.replace(d, plant=plant.name, names=names, scheduling_ops=write_tape(sched))


def _numbers_differ(d: Design, plant: Plant, ts) -> str:
    """Which number the step uses beside the T-S model differs from the plant's ('' if none): the input limits,
    the region (the generated C's accepted range of y), the reference input and the initial state."""
    from .design import u_reference

    limits = None if plant.input_limits is None else np.asarray(plant.input_limits, float)
    mine = None if d.input_limits is None else np.asarray(d.input_limits, float)
    if (limits is None) != (mine is None) or (limits is not None and not np.array_equal(limits, mine)):
        show = lambda a: "none" if a is None else np.array2string(a, precision=6).replace("\n", "")  # noqa: E731
        return f"its input_limits are {show(mine)}, the plant's {show(limits)}"
    region = d.checks.get("region") if isinstance(d.checks, dict) else None
    want = {side: [None if np.isnan(v) else float(v) for v in vals]
            for side, vals in (("lo", plant.region_lo), ("hi", plant.region_hi))}  # fmt: skip
    if region is not None and region != want:
        return (
            f"its checks.region is {region}, the plant's {want} (the region sets the C's accepted range of y)"
        )
    u_ref, x_ref = u_reference(ts, [np.asarray(K, float) for K in d.K], [])
    if (x_ref is None) != (d.x_ref is None) or (
        x_ref is not None and not np.allclose(d.x_ref, x_ref, rtol=1e-12)
    ):
        return f"its x_ref is {d.x_ref}, the plant's {x_ref}"
    u = np.asarray(d.u_ref, float).ravel()
    gap = float(np.max(np.abs(u - u_ref))) if u.shape == u_ref.shape else np.inf
    if not gap <= 1e-6 * max(1.0, float(np.max(np.abs(u_ref)))):
        held = (
            "the input holding the plant at x_ref, less K x_ref"
            if x_ref is not None
            else "the plant's reference"
        )
        return f"its u_ref is {u.tolist()}, not {held}: {np.round(u_ref, 9).tolist()}"
    if d.x0 is not None:
        x0 = np.asarray(d.x0, float).ravel()
        lo = np.where(np.isnan(plant.region_lo), -np.inf, plant.region_lo)
        hi = np.where(np.isnan(plant.region_hi), np.inf, plant.region_hi)
        out = np.flatnonzero((x0 < lo) | (x0 > hi))
        if out.size:
            k = int(out[0])
            return (f"its x0 = {x0.tolist()} lies outside the plant's region ({plant.state_names[k]} = {x0[k]:g} not in "
                    f"[{lo[k]:g}, {hi[k]:g}]), where its T-S model and the observer mean nothing")  # fmt: skip
    return ""


def _convex_memberships(d: Design) -> str:
    """'' when the scheduling map gives memberships h >= 0 with sum 1 at sample points; else what it gives."""
    fn = d.scheduling_function()
    rng = np.random.default_rng(0)
    p, n = int(d.dims.p), int(d.dims.n)
    if fn.n_in() != 2 or fn.nnz_in(0) != p or fn.nnz_in(1) != n or fn.nnz_out(0) != d.r:
        return f"it maps ({fn.nnz_in(0)}, {fn.nnz_in(1)}) to {fn.nnz_out(0)} values, not (y: {p}, xhat: {n}) to r = {d.r}"
    for scale in (1e-3, 1e-1, 1.0, 10.0, 1e3):
        for _ in range(8):
            h = np.asarray(fn(rng.normal(size=p) * scale, rng.normal(size=n) * scale), float).ravel()
            if not (np.all(np.isfinite(h)) and np.all(h >= -1e-12) and abs(h.sum() - 1.0) <= 1e-9):
                return f"its memberships are {np.array2string(h, precision=3)} at a sample point (not >= 0 with sum 1)"
    return ""


def check_loaded(d: Design, plant_option: str | None = None, allow_uncertified: bool = False) -> Trusted:
    """A design read from a document, made fit to use, or :class:`DesignFileError` saying why not.

    ``plant_option``: the plant the user named (``--plant``); ``allow_uncertified``: use a design that does
    not re-certify, marked NOT CERTIFIED (``certified`` False, a status line, a note).
    """
    src = d.loaded.get("source", "the design")
    notes: list[str] = []
    plant, spec = plant_for(d, plant_option)
    if plant is not None:
        d = with_plant(d, plant, spec)
    else:
        notes.append(
            f"note: the document names its plant {d.plant_spec!r}, which fte does not import on a document's word; "
            "the design was not checked against it and its scheduling map is read from the document's data "
            "(name the plant with --plant to check it)"
        )
        if d.scheduling_ops is None:
            raise DesignFileError(
                f"{src} holds its scheduling map only as a serialised CasADi Function (it predates 'scheduling_ops'), "
                f"which fte does not deserialise (it can load a shared library), and its plant {d.plant_spec!r} is not "
                f"a built-in one: name the plant with --plant {d.plant_spec}, or make the document again with "
                "`fte design`"
            )
    if not d.plant_hash:
        notes.append(
            f"note: {src} has no plant_hash (it predates it, or it was removed): it is unchecked against any plant's "
            "fingerprint; "
            + (
                "with its plant loaded it was compared through its T-S model, input limits, reference "
                "and region"
                if plant is not None
                else "name its plant with --plant to compare them"
            )
        )
    bad = _convex_memberships(d)
    if bad:
        raise DesignFileError(f"{src}: its scheduling map ('scheduling_ops') is not a T-S membership map: {bad}; "
                              "make the document again with `fte design`")  # fmt: skip
    reasons = identity_failures(d) + recertify(d)
    if d.loaded.get("certified") is False:
        reasons.insert(0, 'the document says "certified": false')
    if not reasons:
        return Trusted(dataclasses.replace(d, certified=True), plant, spec, notes)
    what = "; ".join(reasons)
    if not allow_uncertified:
        raise DesignFileError(
            f"{src} is not certified at its own numbers: {what}. It is refused: make the design again with "
            "`fte design PLANT -o FILE`, or pass --allow-uncertified to use it anyway (marked NOT CERTIFIED)"
        )
    notes.append(f"WARNING: NOT CERTIFIED: {src} does not re-certify ({what}); used anyway because of "
                 "--allow-uncertified: its estimates and control carry no guarantee")  # fmt: skip
    d = dataclasses.replace(d, certified=False, status=[*d.status, f"NOT CERTIFIED on load: {what}"])
    return Trusted(d, plant, spec, notes)
