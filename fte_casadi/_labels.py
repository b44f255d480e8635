"""Names are data: what a plain label is, and how one is written into C, Markdown and XML.

A label is a name or a unit of a plant (its name, its signals' names and units, its time unit): a line of
printable text that a reader sees as it is. It is checked where it comes in, when a plant is built and when a
design document is loaded (:func:`label_problem`, one validator for both), and escaped again wherever it is
written (:func:`c_comment`, :func:`c_string`, :func:`markdown`, :func:`xml_text`, :func:`plain` for the MAT
file), so that no name, however
it came in, can end a comment, open a string or add a line: the generated C holds no text of a document outside
its comments and string literals.
"""

from __future__ import annotations

import unicodedata

__all__ = ["label_problem", "c_comment", "c_string", "markdown", "xml_text", "plain", "MAX_LABEL"]

#: the longest label (characters): a name or a unit, not a paragraph
MAX_LABEL = 200

#: what a label must not hold, and why (checked in this order)
_SEQUENCES = (
    ("/*", "a C comment opener '/*'"),
    ("*/", "a C comment terminator '*/'"),
    ("//", "a C line comment '//'"),
    ("??", "'??' (a C trigraph starts with it)"),
    ("\\", "a backslash (it joins lines in C)"),
    ("`", "a backquote (it ends code in Markdown)"),
)
#: Unicode categories that are not plain printable text: controls, format characters (such as a
#: right-to-left override), surrogates, private use, unassigned code points, line and paragraph separators
_NOT_TEXT = {"Cc", "Cf", "Cs", "Co", "Cn", "Zl", "Zp"}


def label_problem(text, *, empty: bool = False) -> str:
    """What makes ``text`` no plain label ('' when it is one).

    A label is a string of at most :data:`MAX_LABEL` printable characters on one line, without a C comment
    delimiter (``/*``, ``*/``, ``//``), a trigraph's ``??``, a backslash or a backquote; ``empty`` allows ``""``
    (a unit may be empty).

    Examples
    --------
    >>> label_problem("theta_m"), label_problem("rad/s")
    ('', '')
    >>> label_problem("y1 */ int f(void);")
    "holds a C comment terminator '*/'"
    """
    if not isinstance(text, str):
        return f"is not a string ({type(text).__name__})"
    if not text:
        return "" if empty else "is empty"
    if len(text) > MAX_LABEL:
        return f"is {len(text)} characters long (a label has at most {MAX_LABEL})"
    for ch in text:
        if unicodedata.category(ch) in _NOT_TEXT:
            what = "a line break" if ch in "\n\r\u2028\u2029\x0b\x0c\x85" else "a control or format character"
            return f"holds {what} (U+{ord(ch):04X})"
    for seq, what in _SEQUENCES:
        if seq in text:
            return f"holds {what}"
    return ""


def _escape(ch: str) -> str:
    return f"<U+{ord(ch):04X}>"


def c_comment(text) -> str:
    """``text`` as it may stand inside a C block comment: every character that is not plain printable text,
    every backslash and question mark (a trigraph's ``??/`` is a backslash), and every ``/`` beside a ``*`` or
    another ``/`` written as ``<U+XXXX>``: no comment can end or begin in it, and no line be joined to it."""
    s = "".join(
        _escape(ch) if ch in "\\?" or unicodedata.category(ch) in _NOT_TEXT else ch for ch in str(text)
    )
    return "".join(
        _escape(ch) if ch == "/" and (s[k - 1 : k] == "*" or s[k + 1 : k + 2] in ("*", "/")) else ch
        for k, ch in enumerate(s)
    )


def c_string(text) -> str:
    """``text`` as the body of a C string literal (ASCII; the quotes not included): printable ASCII as it is
    (``"``, ``\\`` and ``?`` escaped), every other byte of its UTF-8 as an octal escape."""
    out = []
    for b in str(text).encode("utf-8"):
        ch = chr(b)
        if ch in '"\\?':
            out.append("\\" + ch)
        elif 0x20 <= b < 0x7F:
            out.append(ch)
        else:
            out.append(f"\\{b:03o}")
    return "".join(out)


def markdown(text) -> str:
    """``text`` as Markdown text, in a code span or outside one: every character that is not plain printable
    text, and the backquote, backslash, ``<``, ``>`` and ``|`` (code, escapes, HTML, tables), written as
    ``<U+XXXX>``: it stays one line of text where it is put."""
    return "".join(
        _escape(ch) if ch in "`\\<>|" or unicodedata.category(ch) in _NOT_TEXT else ch for ch in str(text)
    )


def plain(text) -> str:
    """``text`` with every character that is not plain printable text (a control, a line break, a format
    character such as a right-to-left override) written as ``<U+XXXX>``: one line, as it reads."""
    return "".join(_escape(ch) if unicodedata.category(ch) in _NOT_TEXT else ch for ch in str(text))


def xml_text(text) -> str:
    """``text`` with every character XML 1.0 cannot hold (controls, surrogates, U+FFFE/U+FFFF) written as
    ``<U+XXXX>``; ElementTree escapes ``<``, ``&`` and quotes itself."""
    out = []
    for ch in str(text):
        cp = ord(ch)
        bad = (cp < 0x20 and ch not in "\t") or 0xD800 <= cp <= 0xDFFF or cp in (0xFFFE, 0xFFFF)
        bad |= unicodedata.category(ch) in ("Cc", "Zl", "Zp")
        out.append(_escape(ch) if bad else ch)
    return "".join(out)
