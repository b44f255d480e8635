"""The design document as a MATLAB MAT file (``fte design ... -o design.mat``), for MATLAB/Simulink users.

Every matrix of the JSON document is a variable under its contract name (``H``, ``T``, ``X``, ``P``,
``Kf``, ``Pbar``, ``N``, ``Ls``, ``C``, ``Df``, ``theta`` ...); the per-rule lists (``K``, ``Q``, ``L1``,
``L2``, ``R``, ``Kf_rules`` when present) are cell arrays with one matrix per rule, ``local_models`` a
cell array of structs (``A``, ``B``, ``Bd``, ``Bf``, ``W``, ...), and the dictionaries (``params``,
``dims``, ``checks``, ``observer``, ...) structs. A struct field must be a MATLAB identifier, so a key
such as ``checks.lmi_max_eig["45"]`` becomes the field ``lmi_45``. ``fte_document = 'design'`` marks
the file as one fte wrote (``fte design -o`` replaces only such a file).
"""

from __future__ import annotations

import os
import re

import numpy as np

from .._atomic import atomic_write
from .._labels import plain
from ..errors import DesignFileError

__all__ = []  # public: docs/api.md

#: the variable that marks a MAT file as an fte design document
MARKER = "fte_document"
#: lists with one matrix per rule: cell arrays
_PER_RULE = ("K", "Q", "L1", "L2", "R", "Kf_rules")
_IDENT = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


def _field(key: str, parent: str = "") -> str:
    key = str(key)
    if _IDENT.match(key):
        return key
    stem = "lmi" if parent == "lmi_max_eig" or parent == "lmi_roundoff" else "k"
    return f"{stem}_" + re.sub(r"[^A-Za-z0-9_]", "_", key)


def _cell(items) -> np.ndarray:
    out = np.empty((len(items), 1), dtype=object)
    for k, v in enumerate(items):
        out[k, 0] = v
    return out


def _value(v, parent: str = ""):
    """A JSON value as savemat takes it: matrices as 2-D float arrays, lists of strings or of
    matrices as cell arrays, dicts as structs, None as an empty matrix."""
    if v is None:
        return np.zeros((0, 0))
    if isinstance(v, bool):
        return v
    if isinstance(v, (int, float, str)):
        return v
    if isinstance(v, dict):
        return {_field(k, parent): _value(x, str(k)) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        if not v:
            return np.zeros((0, 0))
        if all(isinstance(x, (int, float)) and not isinstance(x, bool) for x in v):
            return np.asarray(v, dtype=float).reshape(1, -1)
        if all(isinstance(x, list) and all(isinstance(y, (int, float)) for y in x) for x in v):
            return np.asarray(v, dtype=float).reshape(len(v), -1)
        return _cell([_value(x, parent) for x in v])
    raise DesignFileError(f"design document value of type {type(v).__name__} has no MAT form")


def _mat(M) -> np.ndarray:
    a = np.asarray(M, dtype=float)
    return a.reshape(a.shape[0], -1) if a.ndim else a.reshape(1, 1)


def mat_variables(doc: dict) -> dict:
    """The MAT file's variables for a design document (the dict of :meth:`Design.to_dict`)."""
    out = {MARKER: "design"}
    for key, v in doc.items():
        name = _field(key)
        if key in ("plant", "names"):  # names are data: one line of plain text each (fte_casadi._labels)
            v = plain(v) if isinstance(v, str) else {k: _plain_names(x) for k, x in v.items()}
        if key in _PER_RULE:
            out[name] = _cell([_mat(M) for M in v])
        elif key == "local_models":
            out[name] = _cell([{k: _mat(M) for k, M in lm.items()} for lm in v])
        else:
            out[name] = _value(v, key)
    return out


def _plain_names(v):
    if isinstance(v, list):
        return [plain(t) if isinstance(t, str) else t for t in v]
    return plain(v) if isinstance(v, str) else v


def save_mat(doc: dict, path: str | os.PathLike) -> None:
    """Write ``doc`` as a MAT file (version 5, what ``scipy.io.loadmat`` and MATLAB's ``load`` read),
    atomically: a failed write leaves an existing file as it was."""
    from scipy.io import savemat

    variables = mat_variables(doc)
    try:
        atomic_write(path, lambda fh: savemat(fh, variables, do_compression=True, oned_as="column"))
    except OSError as exc:
        raise DesignFileError(f"cannot write the design to {path}: {exc.strerror or exc}") from None


def is_fte_mat(path: str | os.PathLike) -> bool:
    """True when ``path`` is a MAT file that fte wrote (it holds the marker variable)."""
    from scipy.io import loadmat

    try:
        v = loadmat(path, variable_names=[MARKER])
    except Exception:  # noqa: BLE001 - anything unreadable is not ours
        return False
    return MARKER in v and str(np.ravel(v[MARKER])[0]) == "design"
