"""How much a loaded design document is trusted (docs/interface.md, "Trust model").

A document is data. Loading one never runs code it names or holds: its ``plant_spec`` is imported
only when it is a built-in plant's name or when the user names the same plant (``--plant``), and its
scheduling map is rebuilt from that plant, or else replayed from the document's arithmetic tape
(:mod:`fte_casadi.model._tape`), never deserialised. Then the design is re-certified at its own numbers
(:func:`fte_casadi.design._recertify.recertify`) and, when the plant is at hand, checked against it: the
fingerprint of its equations (``plant_hash``) and the local models of its T-S model; its names are then the
plant's.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field

import numpy as np

from .design._recertify import recertify
from .design._record import Design
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
    from .plants import BUILTIN
    from .plants._loader import load_plant

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
    from .model._fingerprint import PARTS, changed_parts
    from .model._tape import write_tape
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
    sched, sources = scheduling_from_measurements(ts)
    names = {
        "states": list(plant.state_names),
        "inputs": list(plant.input_names),
        "outputs": list(plant.output_names),
        "faults": list(plant.fault_names),
        "state_units": list(plant.state_units),
        "output_units": list(plant.output_units),
        "scheduling_sources": sources,
    }  # the plant's names, not the document's: names are data, and the plant is the one the user trusts
    return dataclasses.replace(d, plant=plant.name, names=names, scheduling_ops=write_tape(sched))


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
    bad = _convex_memberships(d)
    if bad:
        raise DesignFileError(f"{src}: its scheduling map ('scheduling_ops') is not a T-S membership map: {bad}; "
                              "make the document again with `fte design`")  # fmt: skip
    reasons = recertify(d)
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
