"""What a Monte Carlo run will take, estimated before anything is allocated, so that a ``--paths`` beyond
the machine's memory is refused with the numbers instead of failing in an allocation."""

from __future__ import annotations

import math
import os

from .errors import ParameterError

__all__ = ["available_memory", "paths_memory", "check_paths_memory"]


def available_memory() -> int | None:
    """Bytes of memory available to a new allocation (Linux: MemAvailable; else the physical memory), or
    None when unknown."""
    try:
        with open("/proc/meminfo") as fh:
            for line in fh:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    try:
        return int(os.sysconf("SC_PHYS_PAGES")) * int(os.sysconf("SC_PAGE_SIZE"))
    except (AttributeError, ValueError, OSError):
        return None


def paths_memory(design, scenario, paths: int, dt: float | None, record_all: bool) -> int:
    """A lower estimate of the bytes a run of ``paths`` paths holds at once: per path its metric
    accumulators (a few numbers per signal of the three runs) and, with ``record_all``, every recorded
    sample of every signal (at most ~2e4 samples per path are kept)."""
    d = design.dims
    signals = int(d.n) + int(d.nbar) + int(d.m) + int(d.p) + int(d.lf)
    per_path = 8 * (3 * signals + 8)
    if record_all:
        step = float(dt or scenario.dt)
        samples = min(int(math.ceil(float(scenario.T) / step)) + 1, 20_001)
        per_path += 8 * samples * 3 * signals
    return int(paths) * per_path


def check_paths_memory(design, scenario, paths: int, dt: float | None, record_all: bool) -> None:
    """Refuse (:class:`ParameterError`, naming the numbers) a run that cannot fit in the available memory."""
    need = paths_memory(design, scenario, paths, dt, record_all)
    have = available_memory()
    if have is not None and need > have:
        per = need / max(int(paths), 1)
        raise ParameterError(
            f"--paths {paths} needs at least {need / 1e9:.3g} GB of memory ({per:.3g} bytes per path"
            + (", every sample kept for --save" if record_all else "")
            + f") and {have / 1e9:.3g} GB is available: use at most about {int(have // per):d} paths, or run them "
            "on a cluster (--scheduler), or leave out --save"
        )
