"""The package's version, in one place: its metadata (pyproject.toml's ``version``, as installed)."""

from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version

__all__ = ["VERSION", "__version__"]

try:
    VERSION = version("fte_casadi")
except PackageNotFoundError:  # a source tree that was never installed: no metadata to read
    VERSION = "0+unknown"

__version__ = VERSION
