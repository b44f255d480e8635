"""Compile a CasADi Function to C and load it back (``ca.external``), with an on-disk cache.

The generated source is hashed; the shared library is kept under the user's cache folder
(``$FTE_CACHE_DIR``, else ``$XDG_CACHE_HOME/fte_casadi``, else ``~/.cache/fte_casadi``), so a
closed loop that was compiled once loads in milliseconds afterwards. Without a C compiler
the interpreted Function is returned and a warning says so.
"""

from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tempfile
import warnings
from pathlib import Path

import casadi as ca

__all__ = ["compiled", "cache_dir"]


def cache_dir() -> Path:
    base = os.environ.get("FTE_CACHE_DIR")
    if base:
        return Path(base)
    xdg = os.environ.get("XDG_CACHE_HOME")
    return (Path(xdg) if xdg else Path.home() / ".cache") / "fte_casadi"


def _compiler() -> str | None:
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return cc
    return None


def compiled(fn: ca.Function, *, flags: tuple[str, ...] = ("-O2",)) -> tuple[ca.Function, bool]:
    """Return ``(function, is_compiled)``: ``fn`` as C in a shared library, or ``fn`` itself."""
    cc = _compiler()
    if cc is None:
        warnings.warn(
            "no C compiler found (cc, gcc, clang or $CC): the Monte Carlo runs interpreted, "
            "10-100x slower; install a C compiler for full speed",
            RuntimeWarning,
            stacklevel=3,
        )
        return fn, False
    name = fn.name()
    with tempfile.TemporaryDirectory() as tmp:
        cg = ca.CodeGenerator(f"{name}.c", {"with_header": False})
        cg.add(fn)
        src_path = Path(tmp) / f"{name}.c"
        cg.generate(str(Path(tmp)) + os.sep)
        src = src_path.read_text()
        key = hashlib.sha256((src + cc + " ".join(flags) + ca.__version__).encode()).hexdigest()[:20]
        folder = cache_dir()
        lib = folder / f"{name}_{key}.so"
        if not lib.exists():
            folder.mkdir(parents=True, exist_ok=True)
            out = Path(tmp) / "lib.so"
            cmd = [cc, *flags, "-shared", "-fPIC", "-o", str(out), str(src_path), "-lm"]
            try:
                proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
            except (OSError, subprocess.TimeoutExpired) as exc:
                proc = None
                err = str(exc)
            if proc is None or proc.returncode != 0:
                err = proc.stderr[-2000:] if proc is not None else err
                warnings.warn(
                    f"compiling the closed loop with {cc} failed; running interpreted (slower). Compiler said: {err}",
                    RuntimeWarning,
                    stacklevel=3,
                )
                return fn, False
            # atomic publish: parallel runs may compile the same library
            fd, tmp_lib = tempfile.mkstemp(dir=folder, suffix=".so.tmp")
            os.close(fd)
            shutil.copyfile(out, tmp_lib)
            os.replace(tmp_lib, lib)
    return ca.external(name, str(lib)), True
