"""Options records beside keyword arguments: the call's record from ``options=`` and the keywords given.

:func:`~fte_casadi.sim.simulate` and :func:`~fte_casadi.tune.tune` take a frozen record of their settings
(:class:`~fte_casadi.sim.SimulateOptions`, :class:`~fte_casadi.tune.TuneOptions`) and keep their keyword
arguments working; :func:`with_keywords` is the one rule that joins the two.
"""

from __future__ import annotations

import dataclasses

from .errors import ParameterError


def _differs(v, default) -> bool:
    """Was a keyword given a value other than its default (a value of another type counts as given)?"""
    if v is default:
        return False
    if type(v) is not type(default):
        return True
    return bool(v != default)


def with_keywords(record_type, options, given: dict):
    """The record a call runs with: ``record_type(**given)`` when ``options`` is None, else ``options`` with the
    keywords of ``given`` that differ from their defaults (a keyword left at its default keeps the record's
    value)."""
    if options is None:
        return record_type(**given)
    if not isinstance(options, record_type):
        raise ParameterError(f"options must be a {record_type.__name__}; got {type(options).__name__}")
    defaults = {f.name: f.default for f in dataclasses.fields(record_type)}
    changes = {k: v for k, v in given.items() if _differs(v, defaults[k])}
    return dataclasses.replace(options, **changes) if changes else options
