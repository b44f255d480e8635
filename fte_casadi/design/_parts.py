"""Typed sub-records of the :class:`~fte_casadi.design._record.Design`: its sizes, parameters and observer.

``Design.dims``, ``Design.params`` and ``Design.observer`` are frozen dataclasses, read by attribute
(``d.dims.n``, ``d.params.sigma``, ``d.observer.alpha``) as diffrax and equinox records are. The design
document (docs/interface.md) does not change: each record writes back exactly the keys it was read from,
in the same order (:meth:`to_dict`), and keeps any key it does not know in ``extra`` (a document written by
a newer version survives a load/save). An optional entry that is absent is ``None``. The records are not
mappings: read attributes, and :meth:`to_dict` for the document's dict.

``Design.checks`` stays a dict: its key set is open (the certificate adds keys with the theorem, the sample
time and Remark 5's fallback, and :func:`~fte_casadi.design.core._certify.failures` reads whatever is there), and
its values are nested reports (``checks["lmi_max_eig"]["46"]``), not scalars a record could type.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from dataclasses import MISSING, dataclass, field
from typing import Any, ClassVar

__all__ = ["Dims", "Params", "Observer"]


class _Record:
    """Shared behaviour: the document's key order and unknown keys kept."""

    #: fields that are not document keys
    _META: ClassVar[tuple[str, ...]] = ("extra", "order")
    #: how one value is written to the document (float for params, int for dims)
    _CAST: ClassVar[Any] = None

    def _fields(self) -> tuple[str, ...]:
        return tuple(f.name for f in dataclasses.fields(self) if f.name not in self._META)

    def keys(self) -> tuple[str, ...]:
        """The document keys this record holds, in the document's order.

        A field is held when the document it came from had it (even as ``null``), or when it is not
        ``None``; unknown keys (``extra``) come last.
        """
        known = self._fields()
        held = [k for k in self.order if k in known or k in self.extra]
        held += [k for k in known if k not in held and getattr(self, k) is not None]
        held += [k for k in self.extra if k not in held]
        return tuple(held)

    def _value(self, key: str):
        return self.extra[key] if key in self.extra else getattr(self, key)

    def to_dict(self) -> dict:
        """The record as the design document writes it (same keys, same order as read)."""
        cast = self._CAST
        return {
            k: (v if cast is None or v is None else cast(v))
            for k, v in ((k, self._value(k)) for k in self.keys())
        }

    def __eq__(self, other: object) -> bool:
        if isinstance(other, _Record):
            return type(self) is type(other) and self.to_dict() == other.to_dict()
        return NotImplemented

    __hash__ = None  # type: ignore[assignment]  # extra is a dict

    def replace(self, **changes) -> _Record:
        """A copy with ``changes``; a key the record does not type goes to ``extra``. Keeps the key order."""
        known = set(self._fields())
        extra = dict(self.extra)
        typed = {}
        for k, v in changes.items():
            if k in known:
                typed[k] = v
            else:
                extra[k] = v
        return dataclasses.replace(self, extra=extra, **typed)

    @classmethod
    def missing(cls, doc: Mapping) -> list[str]:
        """The required keys (fields without a default) that ``doc`` lacks."""
        need = [
            f.name for f in dataclasses.fields(cls) if f.default is MISSING and f.default_factory is MISSING
        ]
        return [k for k in need if k not in doc]

    @classmethod
    def from_mapping(cls, doc: Mapping | _Record | None):
        """The record of a document's entry (a dict); a record is returned as it is; None: empty.

        Values are kept as read (Params: float, Dims: int), so that :meth:`to_dict` writes them back
        unchanged. Raises ``KeyError`` naming a required key that ``doc`` lacks.
        """
        if isinstance(doc, cls):
            return doc
        doc = cls._upgrade(dict(doc or {}))
        for k in cls.missing(doc):
            raise KeyError(k)
        known = {f.name for f in dataclasses.fields(cls)} - set(cls._META)
        typed = {k: cls._convert(k, v) for k, v in doc.items() if k in known}
        extra = {k: v for k, v in doc.items() if k not in known}
        return cls(**typed, extra=extra, order=tuple(doc))

    @classmethod
    def _convert(cls, key: str, value):
        return value

    @classmethod
    def _upgrade(cls, doc: dict) -> dict:
        """``doc`` with the keys of older documents read as today's (same order); the record's own rule."""
        return doc


@dataclass(frozen=True, eq=False)
class Dims(_Record):
    """The design's sizes (``Design.dims``): states, inputs, outputs, unknown inputs, faults, rules, and
    the augmented state ``[x; f'; f'']``.
    """

    n: int
    m: int
    p: int
    ld: int
    lf: int
    r: int
    nbar: int
    extra: dict = field(default_factory=dict, repr=False)
    order: tuple = field(default=(), repr=False)

    _CAST: ClassVar[Any] = int

    @classmethod
    def _convert(cls, key, value):
        return int(value)


@dataclass(frozen=True, eq=False)
class Params(_Record):
    """The LMI parameters the design was solved at (``Design.params``): the attenuation levels ``gamma``,
    ``gamma1``, the coupling weight ``sigma``, the sliding gains ``delta``, ``epsilon``; optional ones are
    ``None`` when not used: ``gamma2`` (Theorem 5's d2 attenuation), ``kappa`` (the bound on cond(Pbar)
    when asked for one), ``boundary_layer`` (the sliding term's ``sat(s/phi)`` width, set by the tuner),
    ``bound_weight`` (the fault-error bound's weight in step 5's objective, when positive), ``beta`` (the
    closed loop's decay rate the registered LMI ``decay`` certifies; absent in older documents: 0).
    """

    gamma: float
    gamma1: float
    sigma: float
    delta: float
    epsilon: float
    gamma2: float | None = None
    kappa: float | None = None
    boundary_layer: float | None = None
    bound_weight: float | None = None
    beta: float | None = None
    extra: dict = field(default_factory=dict, repr=False)
    order: tuple = field(default=(), repr=False)

    _CAST: ClassVar[Any] = float

    @classmethod
    def _convert(cls, key, value):
        return float(value)


@dataclass(frozen=True, eq=False)
class Observer(_Record):
    """How the observer's decay rate was chosen (``Design.observer``), every entry optional (``None``):

    ``sample_time`` the sample time the design was made for (``None`` when none was given),
    ``alpha`` the decay rate used, ``why`` the reason, ``alpha_max`` and ``alpha_max_upper`` the bisection's
    bracket of the largest feasible rate (absent when the user set ``alpha``), ``alpha_before_sample_time`` the
    rate chosen before the sample time lowered it (absent where the sample time did not bind the rate); with the
    fault-error bound in step 5's objective (weight ``Design.params.bound_weight``), the smallest block-diagonal bound (sum of
    squared channel gains) at the observer designed without the term, weight 0
    (``bound_objective_unweighted``), and at the observer designed with it (``bound_objective``). The paper
    variant holds only ``alpha`` (0) and ``why``; documents older than the observer entry hold none.

    Each value is stored once: the largest stable sample time is ``checks.ts_max`` and the bound's weight
    ``params.bound_weight``. Documents written before 0.2.0 also held them here (``observer.ts_max``,
    ``observer.bound_weight``, the same numbers) and named ``bound_objective_unweighted``
    ``bound_objective_before``: they are read as today's (:meth:`_upgrade`) and saved without the copies.
    """

    #: keys of documents before 0.2.0 that held a value stored elsewhere (checks.ts_max, params.bound_weight)
    _DUPLICATES: ClassVar[tuple[str, ...]] = ("ts_max", "bound_weight")
    #: keys of documents before 0.2.0 that have a new name
    _RENAMED: ClassVar[dict[str, str]] = {"bound_objective_before": "bound_objective_unweighted"}

    sample_time: float | None = None
    alpha_max: float | None = None
    alpha_max_upper: float | None = None
    alpha: float | None = None
    why: str | None = None
    alpha_before_sample_time: float | None = None
    bound_objective_unweighted: float | None = None
    bound_objective: float | None = None
    extra: dict = field(default_factory=dict, repr=False)
    order: tuple = field(default=(), repr=False)

    @classmethod
    def _upgrade(cls, doc: dict) -> dict:
        return {cls._RENAMED.get(k, k): v for k, v in doc.items() if k not in cls._DUPLICATES}
