"""Exception classes of fte_casadi.

Every error a user can act on is one of these. They subclass ``ValueError`` or
``TypeError`` so that generic handlers keep working; the CLI turns them into a
one-paragraph message and a non-zero exit status.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ._text import shorten


class FteError(Exception):
    """Base class of every error fte_casadi raises on purpose."""


class PlantError(FteError, ValueError):
    """The plant definition is invalid (shape, linearity, region, parameters)."""


class PlantLoadError(FteError, ValueError):
    """A plant specification (built-in name, ``file.py:function``) cannot be loaded."""


class DerivationError(FteError, ValueError):
    """A T-S model cannot be derived (uncovered nonlinearity, unbounded premise...)."""


class BoundsError(DerivationError):
    """A premise cannot be bounded: ``kind`` is ``"not finite"``, ``"unbounded"`` or ``"constant"``;
    ``where`` names the point (``"x1 = 0"``) for ``"not finite"``, else ``""``."""

    def __init__(self, message: str, kind: str, where: str = ""):
        super().__init__(message)
        self.kind = kind
        self.where = where


class AssumptionError(FteError, ValueError):
    """One of the paper's assumptions (Section 3) fails; the message names it."""


class Refused(enum.Enum):
    """What a design was refused for (:attr:`Refusal.kind`); code decides on these, never on a message's text."""

    #: an LMI is infeasible at the design's parameters (:attr:`Refusal.lmi` names it)
    LMI = "an LMI is infeasible"
    #: a decay rate asked for (the loop's beta, the observer's alpha) is infeasible at the parameters
    DECAY_RATE = "a decay rate asked for is infeasible"
    #: no certified observer runs at the sample time asked for
    SAMPLE_TIME = "no certified observer runs at the sample time"
    #: no certified observer settles within the scenario's shortest fault window
    SETTLE = "no certified observer settles within the fault windows"
    #: the a-posteriori certificate fails at the returned point
    CERTIFICATE = "the certificate fails"


@dataclass(frozen=True)
class Refusal:
    """Why a design was refused, as a record: which LMI, which cause, its numbers, and what to change.

    Code reads the fields (``kind``, ``lmi``, ``bounded``, ``numbers``, ``found``); the message a user reads is
    :meth:`render`, made from them, and never read back.

    ``statement``: what was refused, with its numbers (``"LMI (45) is infeasible: ..."``); ``detail``: what
    bounds it; ``advice``: what to change, ``checked`` when a whole design was run at it and certified;
    ``found``: the cause a diagnosis found behind the refusal (a record with a ``render()``: the plant's diffusion,
    a fault the outputs tell apart only weakly, the cover's vertices), None when none was; ``tried``: values tried
    and refused for other reasons, ``(change, message)`` (``({"sigma": 0.4}, "...")``), said where no advice was
    checked, before the cause found (the search may have passed the statement's LMI and stopped at another: a
    chemostat refused by (45) at sigma = 1 passed it at every smaller sigma tried and failed (46) there). ``lmi`` is
    the key of the registered LMI that decides (``"45"``, ``"46"``; None: no LMI does); ``bounded``: infeasible under the bound kappa on a condition number (a larger bound may
    make it feasible)."""

    kind: Refused
    statement: str
    lmi: str | None = None
    bounded: bool = False
    numbers: Mapping[str, float] = field(default_factory=dict)
    detail: str = ""
    advice: str = ""
    checked: bool = False
    found: Any = None
    tried: tuple = ()

    def render(self) -> str:
        """The message: the statement, what bounds it, the advice (a checked one, or any where no cause was found),
        the values tried (where no advice was checked), and the cause found."""
        tried = (
            "the values tried were refused for other reasons: "
            + "; ".join(
                f"at {', '.join(f'{k} = {v:g}' for k, v in change.items())}: {shorten(why, 700 if self.found is None else 300).rstrip('.')}"
                for change, why in self.tried
            )
            if self.tried and not self.checked
            else ""
        )
        parts = [
            self.statement.rstrip(".")
            if self.detail or self.advice or self.found or tried
            else self.statement
        ]
        parts += [self.detail] if self.detail else []
        parts += [self.advice] if self.advice and (self.checked or self.found is None) else []
        parts += (
            [tried] if tried else []
        )  # what stopped the search past the statement's LMI, before the cause
        parts += [self.found.render()] if self.found is not None else []
        return parts[0] if len(parts) == 1 else ". ".join(parts[:1] + [_capital(p) for p in parts[1:]]) + "."


def _capital(text: str) -> str:
    return text[0].upper() + text[1:] if text else text


class InfeasibleDesignError(FteError, ValueError):
    """The LMI design has no certified solution; the message names the LMI and what to relax.

    ``refusal``: the :class:`Refusal` record the message is rendered from; code reads it, never the message.
    Given a message instead, the refusal is that statement, of ``kind`` (default: an infeasible LMI), with
    ``lmi``, ``bounded`` and ``numbers``. ``result``: the certificate's checks, where the certificate failed.
    ``lmi`` and ``bounded`` are the refusal's."""

    def __init__(self, refusal: Refusal | str, result=None, *, kind: Refused = Refused.LMI, lmi: str | None = None,
                 bounded: bool = False, numbers: Mapping[str, float] | None = None):  # fmt: skip
        if not isinstance(refusal, Refusal):
            refusal = Refusal(kind, str(refusal), lmi=lmi, bounded=bounded, numbers=dict(numbers or {}))
        super().__init__(refusal.render())
        self.refusal = refusal
        self.result = result

    def __reduce__(self):  # pickled with its record (a process pool, a cluster), not rebuilt from the message
        return (type(self), (self.refusal, self.result))

    @property
    def lmi(self) -> str | None:
        return self.refusal.lmi

    @property
    def bounded(self) -> bool:
        return self.refusal.bounded


class SolverFailedError(FteError, RuntimeError):
    """The SDP solver failed numerically (as posed and on rescaled data, with both solvers when the
    design retries); not a proof of infeasibility, so not an :class:`InfeasibleDesignError`. The
    CLI reports it with the same exit status as an infeasible design.

    ``solver_independent``: the failure is in the numpy stages (centring, phase 1), which the other solver would
    repeat exactly, so the design does not retry with it. ``lmi``: the registered LMI whose solve failed, where
    known (``"45"`` in step 3, ``"46"`` in step 5)."""

    def __init__(self, *args, solver_independent: bool = False, lmi: str | None = None):
        super().__init__(*args)
        self.solver_independent = solver_independent
        self.lmi = lmi

    def __reduce__(self):
        return (_solver_failed, (type(self), self.args, self.solver_independent, self.lmi))


def _solver_failed(cls, args, solver_independent, lmi):
    return cls(*args, solver_independent=solver_independent, lmi=lmi)


class CentringError(ArithmeticError):
    """The Newton centring of :mod:`fte_casadi.design.core._sdp` could not start (no strictly feasible
    point) or did not converge. Internal: the design catches it and reports a
    :class:`SolverFailedError` or a note, so it never reaches a user."""


class DesignFileError(FteError, ValueError):
    """A design document is missing, truncated, corrupt or inconsistent."""


class SimulationError(FteError, ValueError):
    """A simulation setting is invalid or a path diverged."""


class UnsupportedOperation(SimulationError):
    """The vectorised Monte Carlo engine cannot emit a Function (an operation the emitter does not
    know), or cannot compile it."""


class CodegenError(FteError, ValueError):
    """C code cannot be generated or written as asked."""


class ParameterError(FteError, ValueError):
    """A numeric setting (gamma, sigma, dt, Ts, paths...) is out of range."""


class MissingDependencyError(FteError, ImportError):
    """An optional dependency (python-control, dask.distributed) is needed and not installed."""


class IntegrationStopped(Exception):
    """Internal: ends an integration of the fidelity check from inside its right-hand side (budget spent, or
    a value not finite); caught where it is raised, never reaches a user."""
