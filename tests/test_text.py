"""Messages quoted in other messages are shortened at a word, never mid-word (fte_casadi/_text.py), and no
message in the package is cut by slicing any more ("(Ts |lambda| must stay well bel.", "centring faile)")."""

from __future__ import annotations

import ast
import pathlib
import re

from hypothesis import given
from hypothesis import strategies as st

from fte_casadi._text import ELLIPSIS, shorten

ROOT = pathlib.Path(__file__).resolve().parents[1] / "fte_casadi"

_WORD = st.text(alphabet=st.characters(min_codepoint=33, max_codepoint=126), min_size=1, max_size=12)


@given(
    st.lists(_WORD, min_size=1, max_size=40), st.integers(5, 120), st.sampled_from([" ", "  ", "\n", " \t"])
)
def test_shortened_at_a_word_within_the_limit(words, limit, sep):
    text = sep.join(words)
    one_line = " ".join(words)
    out = shorten(text, limit)
    assert len(out) <= limit and "\n" not in out
    if len(one_line) <= limit:
        assert out == one_line
    elif out.endswith(ELLIPSIS):
        kept = out[: -len(ELLIPSIS)].split(" ")
        # whole words only: a prefix of the words, the last perhaps without trailing punctuation it ended with
        assert kept[:-1] == words[: len(kept) - 1]
        assert words[len(kept) - 1].startswith(kept[-1]) and words[len(kept) - 1].rstrip(",;:(") == kept[-1]
    else:  # the first word alone is longer than the limit: cut inside it
        assert out.endswith("...") and one_line.startswith(out[:-3]) and " " not in out[:-3].strip()


def test_the_examples_of_the_issue():
    msg = "the discrete observer is unstable (Ts |lambda| must stay well below 2), set by the gains L_i1"
    assert shorten(msg, 60) == "the discrete observer is unstable (Ts |lambda| must stay ..."
    assert (
        shorten("step 5: centring failed at alpha = 0.41 (Newton decrement 3e-3)", 30)
        == "step 5: centring failed at ..."
    )
    assert shorten(ValueError("a   b\n c"), 10) == "a b c"  # an exception's text, on one line
    assert shorten("sin(x1)*cos(x2)*tanh(x3)", 12) == "sin(x1)*c..."  # no word boundary: cut inside the word
    # found by the property test: only punctuation before the boundary; the cut leaves no space before the dots
    assert shorten(": 0 0 0", 5) == ":..."


#: slices that do not cut a message: hashes, and the first parts of a split (a list)
_NOT_MESSAGES = re.compile(r"hexdigest\(\)|\.split\([^()]*\)$")
#: what a sliced value looks like when it is the text of a message
_TEXTY = re.compile(
    r"\bstr\(|\.join\(|\.status\b|\.reason\b|\bexc\b|\bwhy\b|error|stderr|\bmsg\b|message|\btext\b"
)


def _slices_of_text(tree) -> list[tuple[int, str]]:
    """``[:N]`` slices (no start, no step) of a value that reads as a message's text, or inside an f-string."""
    in_fstring = {id(n) for f in ast.walk(tree) if isinstance(f, ast.JoinedStr) for n in ast.walk(f)}
    out = []
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Subscript) and isinstance(node.slice, ast.Slice)):
            continue
        sl = node.slice
        if sl.lower is not None or sl.step is not None or sl.upper is None:
            continue
        value = ast.unparse(node.value)
        if _NOT_MESSAGES.search(value):
            continue
        if id(node) in in_fstring or _TEXTY.search(value):
            out.append((node.lineno, ast.unparse(node)))
    return out


def test_no_message_is_cut_by_slicing():
    found = []
    for path in sorted(ROOT.rglob("*.py")):
        src = path.read_text()
        rel = path.relative_to(ROOT).as_posix()
        found += [f"{rel}:{m.group(0)}" for m in re.finditer(r"str\(\w+\)\)?\[:\s*\d+\s*\]", src)]
        found += [f"{rel}:{line}: {text}" for line, text in _slices_of_text(ast.parse(src))]
    assert found == []


def test_the_check_sees_the_slices_it_is_for():
    for src in ('f"({str(exc)[:120]})"', 'x = " ".join(str(exc).split())[:200]', 'f"{res.status[:120]}"',
                'f"{why[0][1][:300]}"', 'f"{designs[variant][:160]}"', "kind = why[:40]"):  # fmt: skip
        assert _slices_of_text(ast.parse(src)), src
    for src in ("h = hashlib.sha256(b).hexdigest()[:20]", "z = zz[:nbar]", "a = order[:10]",
                "k = ':'.join(reason.split(':')[:2])"):  # fmt: skip
        assert not _slices_of_text(ast.parse(src)), src
