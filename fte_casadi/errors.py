"""Exception classes of fte_casadi.

Every error a user can act on is one of these. They subclass ``ValueError`` or
``TypeError`` so that generic handlers keep working; the CLI turns them into a
one-paragraph message and a non-zero exit status.
"""

from __future__ import annotations


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


class InfeasibleDesignError(FteError, ValueError):
    """The LMI design has no certified solution; the message names the LMI and what to relax.

    ``lmi``: the registered LMI that is infeasible, where one is (``"45"``, ``"46"``; None: another cause);
    ``bounded``: True when it was infeasible under the bound kappa on cond(X') or cond(Pbar) (a larger bound may
    make it feasible). Code reads these fields, never the message."""

    def __init__(self, message: str, result=None, *, lmi: str | None = None, bounded: bool = False):
        super().__init__(message)
        self.result = result
        self.lmi = lmi
        self.bounded = bounded


class SolverFailedError(FteError, RuntimeError):
    """The SDP solver failed numerically (as posed and on rescaled data, with both solvers when the
    design retries); not a proof of infeasibility, so not an :class:`InfeasibleDesignError`. The
    CLI reports it with the same exit status as an infeasible design.

    ``solver_independent``: the failure is in the numpy stages (centring, phase 1), which the other solver would
    repeat exactly, so the design does not retry with it."""

    def __init__(self, *args, solver_independent: bool = False):
        super().__init__(*args)
        self.solver_independent = solver_independent


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
