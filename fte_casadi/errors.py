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


class AssumptionError(FteError, ValueError):
    """One of the paper's assumptions (Section 3) fails; the message names it."""


class InfeasibleDesignError(FteError, ValueError):
    """The LMI design has no certified solution; the message names the LMI and what to relax."""

    def __init__(self, message: str, result=None):
        super().__init__(message)
        self.result = result


class DesignFileError(FteError, ValueError):
    """A design document is missing, truncated, corrupt or inconsistent."""


class SimulationError(FteError, ValueError):
    """A simulation setting is invalid or a path diverged."""


class CodegenError(FteError, ValueError):
    """C code cannot be generated or written as asked."""


class ParameterError(FteError, ValueError):
    """A numeric setting (gamma, sigma, dt, Ts, paths...) is out of range."""


class MissingDependencyError(FteError, ImportError):
    """An optional dependency (python-control, dask.distributed) is needed and not installed."""
