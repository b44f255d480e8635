"""What every command shares: exit statuses and the guard that turns errors into one paragraph,
the report of the files written before a Ctrl-C, and checks of common arguments and output files."""

from __future__ import annotations

import functools
import json
import os
import sys
import textwrap
from pathlib import Path

import click
import numpy as np

from .. import _interrupt
from ..errors import FteError, InfeasibleDesignError, ParameterError, SolverFailedError

EXIT_BAD_INPUT = 2
EXIT_FAILED = 1


def _fail(message: str, code: int = EXIT_BAD_INPUT) -> None:
    click.echo(
        textwrap.fill("fte: " + " ".join(message.split()), width=100, break_on_hyphens=False), err=True
    )
    sys.exit(code)


def _ours(path: Path) -> bool:
    """True when ``path`` holds something fte wrote: a design document (JSON or MAT) or a saved result (.npz)."""
    import zipfile

    from ..design import REQUIRED_KEYS

    if path.suffix.lower() == ".mat":
        from ..design import is_fte_mat

        return is_fte_mat(path)
    try:
        if zipfile.is_zipfile(path):
            with zipfile.ZipFile(path) as z:
                return {"meta.npy", "design.npy", "scenario.npy"} <= set(z.namelist())
        doc = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, ValueError, RecursionError, zipfile.BadZipFile):
        return False
    return isinstance(doc, dict) and all(k in doc for k in REQUIRED_KEYS)


def _writable_target(path: str, option: str, what: str) -> None:
    """Refuse, before any work, to overwrite a file fte did not write (a plant file, a user's data);
    a directory gets a hint. An earlier fte output is replaced, as ``-o`` promises."""
    p = Path(path)
    if p.is_dir():
        raise ParameterError(f"{option} {path} is a directory; give a file name such as {p / what}")
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.is_dir():
        raise ParameterError(f"{option} {path}: the directory {folder} does not exist (checked before any work); "
                             "create it first, or give a file in an existing directory")  # fmt: skip
    if not os.access(folder, os.W_OK | os.X_OK):
        raise ParameterError(f"{option} {path}: the directory {folder} is not writable (checked before any work); "
                             "give a file in a writable directory")  # fmt: skip
    if p.exists() and not _ours(p):
        raise ParameterError(
            f"{option} {path} exists and was not written by fte (it is not a {what.split('.')[0]} document): it is "
            "left untouched; choose another file name, or move that file away first"
        )


def _stat_tree(path: Path) -> dict[str, tuple]:
    """Every file at or under ``path``: its identity, time and size (a file renamed into place is a new identity)."""
    out = {}
    try:
        for f in [path] if path.is_file() else path.rglob("*") if path.is_dir() else []:
            if f.is_file():
                st = f.stat()
                out[str(f)] = (st.st_ino, st.st_mtime_ns, st.st_size)
    except OSError:
        pass
    return out


def _outputs(*targets) -> None:
    """Note the files and folders this command may write: after a Ctrl-C the message lists exactly
    those of them that changed (each complete: every file is renamed into place whole)."""
    meta = click.get_current_context().meta.setdefault("fte.outputs", {})
    for t in targets:
        if t is not None and Path(t) not in meta:
            meta[Path(t)] = _stat_tree(Path(t))


def _interrupted() -> str:
    """What was written before a Ctrl-C, from the snapshot :func:`_outputs` took, and what to do next."""
    ctx = click.get_current_context(silent=True)
    meta = ctx.meta if ctx is not None else {}
    written, removed = [], []
    for path, before in meta.get("fte.outputs", {}).items():
        after = _stat_tree(path)
        written += sorted(f for f, v in after.items() if before.get(f) != v)
        removed += sorted(f for f in before if f not in after)

    def some(names: list[str]) -> str:
        return ", ".join(names[:8]) + (f" and {len(names) - 8} more" if len(names) > 8 else "")

    parts = [f"written before the interrupt, each file complete: {some(written)}"] if written else []
    parts += [f"removed: {some(removed)}"] if removed else []
    if parts:
        msg = "interrupted; " + "; ".join(parts) + "; nothing else was written"
    else:
        msg = "interrupted; nothing was written (earlier files are as they were)"
    note = meta.get("fte.on_interrupt")
    return msg + (f"; {note()}" if note else "")


def _guard(fn):
    """Run a command; on a known error print one paragraph and exit non-zero (130 after a Ctrl-C,
    saying exactly which files were written). A Ctrl-C wins over anything else: the command's result, or an
    error that a swallowed ``KeyboardInterrupt`` caused (CasADi's, a solver's), ends with 130 too."""

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        debug = click.get_current_context().find_root().params.get("debug", False)
        try:
            rv = fn(*args, **kwargs)
        except BrokenPipeError:  # output piped into `head` and the like
            sys.stderr.close()
            sys.exit(0)
        except KeyboardInterrupt:
            _fail(_interrupted(), 130)
        except (InfeasibleDesignError, SolverFailedError) as exc:
            if _interrupt.pending():
                _fail(_interrupted(), 130)
            if debug:
                raise
            _fail(str(exc), EXIT_FAILED)
        except FteError as exc:
            if _interrupt.pending():
                _fail(_interrupted(), 130)
            if debug:
                raise
            _fail(str(exc), EXIT_BAD_INPUT)
        except MemoryError:
            if _interrupt.pending():
                _fail(_interrupted(), 130)
            if debug:
                raise
            _fail("out of memory: the run asks for more than this machine has; use fewer --paths (or a cluster "
                  "with --scheduler), or leave out --save")  # fmt: skip
        except Exception as exc:  # noqa: BLE001 - the last line of defence: no traceback for users
            if _interrupt.pending():  # CasADi turns an interrupt into an error of its own
                _fail(_interrupted(), 130)
            if debug:
                raise
            _fail(
                f"internal error {type(exc).__name__}: {exc}. This is a bug in fte_casadi or an unexpected "
                "input; run again with `fte --debug ...` to see where, and report it",
                3,
            )
        if _interrupt.pending():  # the interrupt was swallowed on the way: it still wins
            _fail(_interrupted(), 130)
        return rv

    return wrapper


def _check_seed(seed: int) -> None:
    """A seed numpy's generators take: 0 <= seed < 2**63."""
    if not 0 <= seed < 2**63:
        raise ParameterError(f"--seed must be an integer from 0 to 2**63 - 1 = {2**63 - 1}; got {seed}")


def _check_paths(paths: int | None) -> None:
    """--paths, when given, is a positive integer."""
    if paths is not None and paths < 1:
        raise ParameterError(f"--paths must be a positive integer; got {paths}")


def _positive(name: str, value, allow_zero: bool = False):
    if value is None:
        return None
    if not np.isfinite(value) or value < 0 or (value == 0 and not allow_zero):
        what = "a finite number >= 0" if allow_zero else "a positive finite number"
        raise ParameterError(f"--{name.replace('_', '-')} must be {what}; got {value}")
    return value
