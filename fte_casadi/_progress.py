"""What long work is doing, where its length is not known in advance (a design's parameter search).

The library says what it starts (:func:`note`), and which stages hold the steps after it (:func:`stage`: a
trial of the parameter search holds a whole design); whoever runs it decides whether and how to show it
(:func:`reporting`). The ``fte`` command shows the latest on a status line; a library user sees nothing unless
they ask. Reporter and stages live in context variables: nothing is shared between threads or left behind after
the call that installed them.
"""

from __future__ import annotations

import contextlib
from collections.abc import Callable, Iterator
from contextvars import ContextVar

__all__ = ["note", "stage", "reporting", "SEPARATOR"]

#: between a stage and what runs inside it, in what the reporter is given
SEPARATOR = " > "

_reporter: ContextVar[Callable[[str], None] | None] = ContextVar("fte_progress", default=None)
_stages: ContextVar[tuple[str, ...]] = ContextVar("fte_progress_stages", default=())


def note(what: str) -> None:
    """Tell the reporter in force (if any) that ``what`` starts now, within the stages open."""
    fn = _reporter.get()
    if fn is not None:
        fn(SEPARATOR.join((*_stages.get(), what)))


@contextlib.contextmanager
def stage(what: str) -> Iterator[None]:
    """A stage that holds the notes made within the block (noted itself as it opens)."""
    note(what)
    token = _stages.set((*_stages.get(), what))
    try:
        yield
    finally:
        _stages.reset(token)


@contextlib.contextmanager
def reporting(fn: Callable[[str], None]) -> Iterator[None]:
    """Within the block, :func:`note` calls ``fn(what)``, ``what`` the stages open and the note joined by
    :data:`SEPARATOR`; the reporter before it is restored after."""
    token = _reporter.set(fn)
    try:
        yield
    finally:
        _reporter.reset(token)
