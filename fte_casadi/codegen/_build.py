"""Compile generated C with the strict flags of docs/interface.md (for ctypes tests, examples, benchmarks)."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from .._toolchain import find_compiler as find_compiler
from ..errors import CodegenError

__all__ = ["find_compiler", "compile_shared", "compile_program"]  # public: docs/api.md

#: the flags every generated file must compile under, with no warning
STRICT_FLAGS = ("-std=c99", "-O2", "-Wall", "-Wextra", "-Werror", "-pedantic")


def _require_compiler() -> str:
    cc = find_compiler()
    if cc is None:
        raise CodegenError(
            "no C compiler found (looked for $CC, cc, gcc, clang on PATH); install one, e.g. "
            "`apt-get install gcc`, or set CC"
        )
    return cc


def _sources(src_dir: str | os.PathLike) -> list[str]:
    files = sorted(str(p) for p in Path(src_dir).glob("*.c"))
    if not files:
        raise CodegenError(f"no .c files in {str(src_dir)!r}; generate them first with `fte codegen`")
    return files


def _run(cmd: list[str]) -> None:
    proc = subprocess.run(cmd, capture_output=True, text=True)
    if proc.returncode != 0:
        raise CodegenError(f"compilation failed: {' '.join(cmd)}\n{proc.stderr.strip()}")


def compile_shared(src_dir: str | os.PathLike, out: str | os.PathLike, *, extra_flags=()) -> Path:
    """Compile every ``src_dir/*.c`` with :data:`STRICT_FLAGS` into a shared library ``out``."""
    cc = _require_compiler()
    flag = "-dynamiclib" if sys.platform == "darwin" else "-shared"
    cmd = [cc, *STRICT_FLAGS, "-fPIC", flag, *extra_flags, *_sources(src_dir), "-o", str(out), "-lm"]
    _run(cmd)
    return Path(out)


def compile_program(
    src_dir: str | os.PathLike,
    main_c: str | os.PathLike,
    out: str | os.PathLike,
    *,
    extra_flags=(),
    extra_sources=(),
) -> Path:
    """Compile ``src_dir/*.c`` together with a caller's ``main_c`` (strict flags) into ``out``."""
    cc = _require_compiler()
    cmd = [
        cc,
        *STRICT_FLAGS,
        *extra_flags,
        f"-I{src_dir}",
        *_sources(src_dir),
        *[str(s) for s in extra_sources],
        str(main_c),
        "-o",
        str(out),
        "-lm",
    ]
    _run(cmd)
    return Path(out)


def run_program(exe: str | os.PathLike, *args: str, timeout: float = 60.0) -> str:
    """Run a compiled program and return its standard output (CodegenError on a non-zero exit)."""
    proc = subprocess.run([str(exe), *args], capture_output=True, text=True, timeout=timeout)
    if proc.returncode != 0:
        raise CodegenError(f"{exe} exited with status {proc.returncode}: {proc.stderr.strip()}")
    return proc.stdout
