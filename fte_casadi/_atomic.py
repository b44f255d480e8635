"""Files and folders written whole or not at all.

Every file fte writes goes through :func:`atomic_write`: the content is written to a temporary file
in the target's folder, flushed to disk, and renamed over the target (``os.replace``, atomic on
POSIX and Windows). A kill, a Ctrl-C or a full disk at any moment leaves the previous file or the
complete new one, never a partial one; an interrupted write removes its temporary file (a SIGKILL
can leave one behind, named ``.NAME.*.tmp``). After a Ctrl-C of the ``fte`` command nothing more is put in
place (:func:`fte_casadi._interrupt.check`), even where the ``KeyboardInterrupt`` was swallowed.

:func:`replace_dir` does the same for a folder written as a set (``fte tune``'s output), and
:func:`write_set` for files written as a set into a folder that may hold other files too (``fte codegen``).
"""

from __future__ import annotations

import ctypes
import os
import shutil
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import BinaryIO

from ._interrupt import check as _not_interrupted

__all__ = ["atomic_write", "atomic_write_text", "replace_dir", "write_set", "file_mode"]


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The permission bits of a newly created file (``0o666`` less the umask): what ``open`` gives."""
    return 0o666 & ~_umask()


def _folder(path: Path) -> Path:
    return path.parent if str(path.parent) else Path(".")


def _sync_folder(folder: Path) -> None:
    """Flush a folder's entries (the rename) to disk where the system allows it."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write(path: str | os.PathLike, write: Callable[[BinaryIO], object]) -> Path:
    """Write ``path`` through ``write(fh)``, ``fh`` a binary file open on a temporary file beside it,
    then rename that file over ``path``.

    ``write`` may be anything that writes to a binary file object (``np.savez``,
    ``scipy.io.savemat``, ``Figure.savefig``). Any error, ``KeyboardInterrupt`` included, removes the
    temporary file and leaves an existing ``path`` as it was. The new file gets the mode an existing
    ``path`` had, else the mode ``open`` would give.

    Examples
    --------
    >>> import tempfile, pathlib
    >>> p = pathlib.Path(tempfile.mkdtemp()) / "a.txt"
    >>> _ = atomic_write(p, lambda fh: fh.write(b"whole"))
    >>> p.read_bytes()
    b'whole'
    """
    path = Path(path)
    folder = _folder(path)
    try:
        mode = path.stat().st_mode & 0o7777
    except OSError:
        mode = file_mode()
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=folder)
    try:
        with os.fdopen(fd, "wb") as fh:
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, mode)
        _not_interrupted()  # after a Ctrl-C nothing is put in place, whoever swallowed its KeyboardInterrupt
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    _sync_folder(folder)
    return path


def atomic_write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` with :func:`atomic_write`."""
    data = text.encode("utf-8")
    return atomic_write(path, lambda fh: fh.write(data))


#: ``renameat2``'s flag that swaps two names in one step (Linux 3.15+, glibc 2.28+)
_RENAME_EXCHANGE = 2
_AT_FDCWD = -100


def _exchange(a: Path, b: Path) -> bool:
    """Swap the names ``a`` and ``b`` in one step; False where the system cannot."""
    try:
        renameat2 = ctypes.CDLL(None, use_errno=True).renameat2
    except (OSError, AttributeError):
        return False
    renameat2.argtypes = (ctypes.c_int, ctypes.c_char_p, ctypes.c_int, ctypes.c_char_p, ctypes.c_uint)
    rc = renameat2(_AT_FDCWD, os.fsencode(a), _AT_FDCWD, os.fsencode(b), _RENAME_EXCHANGE)
    return rc == 0


def replace_dir(new: str | os.PathLike, target: str | os.PathLike) -> Path:
    """Put the folder ``new`` in the place of ``target`` as one set, then delete the old ``target``.

    Where the system can swap two names in one step (Linux), a kill at any moment leaves the old
    folder or the new one at ``target``. Elsewhere the old folder is renamed aside
    (``.NAME.old-*``) before the new one is renamed in: a kill between the two renames leaves
    ``target`` missing and both folders beside it. ``new`` and ``target`` must share a parent folder.
    """
    new, target = Path(new), Path(target)
    _not_interrupted()
    if not target.exists():
        os.rename(new, target)
    elif _exchange(new, target):
        shutil.rmtree(new)  # now the old folder
    else:
        old = Path(tempfile.mkdtemp(prefix=f".{target.name}.old-", dir=_folder(target)))
        os.rename(target, old / "dir")
        os.rename(new, target)
        shutil.rmtree(old)
    _sync_folder(_folder(target))
    return target


def write_set(folder: str | os.PathLike, files: dict[str, bytes]) -> list[Path]:
    """Put ``files`` (name: content) into ``folder`` as one set: a kill at any moment leaves all of them new or
    all of them as they were, never a mix.

    The new folder is made beside ``folder``: every other entry of ``folder`` carried over as hard links (the
    same files, not copies; a folder in it as a tree of hard links), then the new files written and flushed;
    it then replaces ``folder`` by :func:`replace_dir` (one swap where the system can). ``folder`` and the
    folders above it are created if needed; a ``folder`` that holds the current directory cannot be swapped
    (``ValueError``). Returns the paths of ``files`` in ``folder``.
    """
    target = Path(os.path.abspath(folder))
    if target.is_symlink():
        target = target.resolve()
    here = Path.cwd().resolve()
    if target.exists() and target.resolve() in (here, *here.parents):
        raise ValueError(f"{folder} is the current directory or holds it")
    target.parent.mkdir(parents=True, exist_ok=True)
    new = Path(tempfile.mkdtemp(prefix=f".{target.name}.new-", dir=target.parent))
    try:
        if target.is_dir():
            for entry in os.scandir(target):
                if entry.name in files:
                    continue
                if entry.is_dir(follow_symlinks=False):
                    shutil.copytree(entry.path, new / entry.name, symlinks=True, copy_function=os.link)
                else:
                    os.link(entry.path, new / entry.name, follow_symlinks=False)
            shutil.copymode(target, new)
        else:
            os.chmod(new, 0o777 & ~_umask())  # what mkdir gives (mkdtemp gives 0o700)
        mode = file_mode()
        for name, data in files.items():
            with open(new / name, "wb") as fh:
                fh.write(data)
                fh.flush()
                os.fsync(fh.fileno())
            os.chmod(new / name, mode)
        _sync_folder(new)
        replace_dir(new, target)
    except BaseException:
        shutil.rmtree(new, ignore_errors=True)
        raise
    return [target / name for name in files]
