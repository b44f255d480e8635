"""Text a user reads: a message quoted inside another, shortened at a word, never mid-word."""

from __future__ import annotations

__all__ = ["shorten"]

#: what marks a shortened text
ELLIPSIS = " ..."


def shorten(text: object, limit: int) -> str:
    """``text`` (an exception, a status, any object: its ``str``) on one line, whitespace collapsed, and when it is
    longer than ``limit`` characters cut at the last word boundary that leaves room for ``" ..."``. A single word
    longer than that (an expression such as ``sin(x1)*cos(x2)...``) is cut inside it, still within ``limit``.

    >>> shorten("the centring failed at alpha = 0.5", 24)
    'the centring failed ...'
    >>> shorten("short", 24)
    'short'
    >>> shorten("x" * 30, 10)
    'xxxxxxx...'
    """
    s = " ".join(str(text).split())
    if len(s) <= limit:
        return s
    room = max(limit - len(ELLIPSIS), 0)
    head = s[: room + 1]  # one more character: a word that ends exactly at the cut is kept whole
    cut = head.rsplit(" ", 1)[0] if " " in head else ""
    cut = cut.rstrip(" ,;:(")
    if not cut:  # no word boundary before the limit (or only punctuation before it): cut inside the word
        return s[: max(limit - 3, 0)].rstrip() + "..."
    return cut + ELLIPSIS
