"""Ctrl-C for the ``fte`` command: an interrupt is remembered, whoever catches the exception it raises.

Python turns a SIGINT into a ``KeyboardInterrupt`` in the main thread, and some code swallows it: CasADi
returns ``None`` from a call it interrupted, SCS installs its own handler while it solves and reports a solver
failure, a library's ``except Exception`` retries. So the command records the SIGINT itself
(:func:`handling`): the guard of every command then ends with status 130 whatever exception, or none, follows,
and :func:`check`, called before every file is put in place (:mod:`fte_casadi._atomic`, the generated C's
folder), refuses to write one after the interrupt. A library user's process is not touched: nothing is
installed unless the command runs, and :func:`pending` is False outside it.

:func:`quiet_loading` covers the instant before the command runs: a Ctrl-C while the package's modules load
ends the process with status 130 and one line, not a traceback, also where a library swallows it or turns it into
another error while it loads (scipy's HiGHS extension reports "ImportError: initialization failed"): the SIGINT is
recorded while the modules load, and :func:`loaded`, at the end of the package's ``__init__``, restores Python's
handler and raises the interrupt that was swallowed.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
import threading

__all__ = ["handling", "pending", "check", "interrupted", "quiet_loading", "loaded"]


class _State:
    """The one piece of process state: whether a SIGINT came while :func:`handling` was in force."""

    seen = False
    active = False
    #: a SIGINT came while the package's modules loaded (:func:`quiet_loading`)
    loading = False


def pending() -> bool:
    """True when a Ctrl-C came while the command ran (False outside the ``fte`` command)."""
    return _State.active and _State.seen


def interrupted() -> KeyboardInterrupt:
    """Record an interrupt that reached fte by another way than the signal (a solver that caught the SIGINT
    and reported it as its status) and return the exception to raise."""
    _State.seen = True
    return KeyboardInterrupt()


def check() -> None:
    """Raise ``KeyboardInterrupt`` when a Ctrl-C came (a file is not put in place after one)."""
    if pending():
        raise KeyboardInterrupt


def _on_sigint(signum, frame) -> None:
    _State.seen = True
    raise KeyboardInterrupt


@contextlib.contextmanager
def handling():
    """Within: a SIGINT is recorded (:func:`pending`) before it raises ``KeyboardInterrupt``; the handler
    before is restored on exit. In a thread other than the main one (where no handler can be installed) only
    the record of :func:`interrupted` works."""
    main = threading.current_thread() is threading.main_thread()
    before = signal.getsignal(signal.SIGINT) if main else None
    _State.seen, _State.active = False, True
    if main:
        signal.signal(signal.SIGINT, _on_sigint)
    try:
        yield
    finally:
        if main:
            signal.signal(signal.SIGINT, before if before is not None else signal.default_int_handler)
        _State.active = False


def _while_loading(previous):
    """A ``sys.excepthook`` that ends the process with status 130 and one line when a ``KeyboardInterrupt``
    escapes while fte_casadi's modules load (a module-level frame of the package in its traceback); anything
    else goes to ``previous``."""
    package = os.path.dirname(os.path.abspath(__file__))

    def hook(kind, value, tb):
        loading, t = False, tb
        while t is not None:
            code = t.tb_frame.f_code
            loading |= code.co_name == "<module>" and os.path.abspath(code.co_filename).startswith(package)
            t = t.tb_next
        if loading and (issubclass(kind, KeyboardInterrupt) or _State.loading):
            with contextlib.suppress(Exception):
                sys.stderr.write("fte: interrupted while loading; nothing was written\n")
                sys.stderr.flush()
            os._exit(130)
        previous(kind, value, tb)

    hook.fte_loading = True
    return hook


def _on_sigint_loading(signum, frame) -> None:
    _State.loading = True
    raise KeyboardInterrupt


def _main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def quiet_loading() -> None:
    """Make a Ctrl-C while the package loads end the process quietly (:func:`_while_loading`; once), and record
    it (where Python's own handler is in force, in the main thread) until :func:`loaded`."""
    if not getattr(sys.excepthook, "fte_loading", False):
        sys.excepthook = _while_loading(sys.excepthook)
    if _main_thread() and signal.getsignal(signal.SIGINT) is signal.default_int_handler:
        signal.signal(signal.SIGINT, _on_sigint_loading)


def loaded() -> None:
    """The modules are loaded: Python's handler again, and an interrupt that came while they loaded and that a
    library swallowed is raised now (the hook of :func:`quiet_loading` ends the process with status 130)."""
    if _main_thread() and signal.getsignal(signal.SIGINT) is _on_sigint_loading:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if _State.loading:
        _State.loading = False
        raise KeyboardInterrupt


quiet_loading()  # imported first by fte_casadi/__init__.py: in force while the rest of the package loads
