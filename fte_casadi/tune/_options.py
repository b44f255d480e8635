"""The settings of a search (:class:`TuneOptions`), in the style of the design's
:class:`~fte_casadi.design.DesignOptions`: one frozen record, checked once on construction, changed with
:meth:`TuneOptions.replace`. :func:`~fte_casadi.tune.tune` takes it as ``options=`` beside its keyword
arguments, which keep working (:func:`fte_casadi._keywords.with_keywords`)."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from ..errors import ParameterError

__all__ = ["TuneOptions"]  # public: docs/api.md

#: the rules of :func:`~fte_casadi.tune.choose`
RULES = ("balanced", "fault-error", "false-alarm", "ftc", "bound")


def _integer(v, least: int) -> bool:
    return isinstance(v, int) and not isinstance(v, bool) and v >= least


@dataclass(frozen=True)
class TuneOptions:
    """How :func:`~fte_casadi.tune.tune` searches, beyond the base design, the plant and the scenario.

    Checked once, on construction (:class:`~fte_casadi.errors.ParameterError` naming the field and, in
    brackets, the ``fte tune`` option that sets it). Change one with :meth:`replace`.

    Parameters
    ----------
    trials : int
        Trials in all, trial 0 (the base design) included (>= 2).
    seed : int
        Seed of the sampler and of the Monte Carlo (>= 0; default 0).
    rule : str
        One of :data:`RULES` (default ``"balanced"``): how the chosen design is picked from the front.
    paths : int, optional
        Monte Carlo paths per candidate (>= 1; default: 20, or the scenario's when more).
    scheduler : str or distributed.Client, optional
        Run the candidates on a dask.distributed cluster.
    sigma_sup : float, optional
        The largest sigma (45) allows for any gamma (positive; caps the sigma range; default: computed).
    base_is_given : bool
        Has no effect on the search: trial 0 is always the base design as it is.
    progress : callable, optional
        ``progress(done, total)`` after each trial.
    storage : str, optional
        An optuna storage URL (``sqlite:///DIR/optuna.db``) where every trial is kept as it finishes; default:
        in memory.
    resume : bool
        Continue the search kept in ``storage`` (when it holds one; else start afresh).

    Examples
    --------
    >>> o = TuneOptions(trials=8, seed=3)
    >>> o.replace(rule="ftc").rule, o.paths is None
    ('ftc', True)
    """

    trials: int
    seed: int = 0
    rule: str = "balanced"
    paths: int | None = None
    scheduler: Any = None
    sigma_sup: float | None = None
    base_is_given: bool = False
    progress: Callable[[int, int], None] | None = None
    storage: str | None = None
    resume: bool = False

    def __post_init__(self):
        if not _integer(self.trials, 2):
            raise ParameterError(
                f"trials (--trials) must be an integer >= 2 (trial 0 is the base design); got {self.trials!r}"
            )
        if not _integer(self.seed, 0):
            raise ParameterError(f"seed (--seed) must be a non-negative integer; got {self.seed!r}")
        if self.rule not in RULES:
            raise ParameterError(
                f"unknown rule (--objective) {self.rule!r}; choose one of {', '.join(RULES)}"
            )
        if self.paths is not None and not _integer(self.paths, 1):
            raise ParameterError(
                f"paths (--paths) must be a positive integer (or None: 20, or the scenario's when more); "
                f"got {self.paths!r}"
            )
        s = self.sigma_sup
        if s is not None and not (
            isinstance(s, (int, float)) and not isinstance(s, bool) and math.isfinite(s) and s > 0
        ):
            raise ParameterError(
                f"sigma_sup (the largest sigma (45) allows) must be a positive number; got {s!r}"
            )
        for k in ("base_is_given", "resume"):
            if not isinstance(getattr(self, k), bool):
                raise ParameterError(f"{k} must be True or False; got {getattr(self, k)!r}")
        if self.progress is not None and not callable(self.progress):
            raise ParameterError(f"progress must be a function progress(done, total); got {self.progress!r}")
        if self.storage is not None and not isinstance(self.storage, str):
            raise ParameterError(
                f"storage must be an optuna storage URL (e.g. sqlite:///DIR/optuna.db); got {self.storage!r}"
            )

    def replace(self, **changes) -> TuneOptions:
        """This record with ``changes`` (:func:`dataclasses.replace`)."""
        return dataclasses.replace(self, **changes)
