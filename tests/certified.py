"""How a test asserts that ``fte design`` certified its design: the verdict of the summary line and the
document's own numbers (``"CERTIFIED" in stdout`` would also be true of "NOT CERTIFIED")."""

from __future__ import annotations

import json
import re
from pathlib import Path

#: the first line of ``fte design``'s summary (fte_casadi/design/_summary.py)
VERDICT = re.compile(r"^design of .+, solver \S+, (NOT CERTIFIED|CERTIFIED)$", re.MULTILINE)


def verdict(stdout: str) -> str | None:
    """The verdict of the summary line in ``stdout`` ("CERTIFIED" or "NOT CERTIFIED"), None without one."""
    found = VERDICT.findall(stdout)
    return found[-1] if found else None


def assert_certified(stdout: str, document: str | Path | None = None) -> None:
    """The summary says CERTIFIED and, given the written document, it says ``certified: true`` and every
    LMI's recorded largest eigenvalue is negative."""
    assert verdict(stdout) == "CERTIFIED", stdout
    if document is not None:
        doc = json.loads(Path(document).read_text())
        assert doc["certified"] is True
        lmi = doc["checks"]["lmi_max_eig"]
        assert lmi and all(isinstance(v, float) and v < 0 for v in lmi.values()), lmi
