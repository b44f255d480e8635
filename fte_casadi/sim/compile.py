"""Where compiled closed loops are kept on disk.

The vectorised engine (:mod:`.vector`) hashes the C it generates and keeps the shared library under
the user's cache folder (``$FTE_CACHE_DIR``, else ``$XDG_CACHE_HOME/fte_casadi``, else
``~/.cache/fte_casadi``), so a closed loop that was compiled once loads in milliseconds afterwards.
"""

from __future__ import annotations

import os
from pathlib import Path

__all__ = ["cache_dir"]


def cache_dir() -> Path:
    base = os.environ.get("FTE_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fte_casadi"
