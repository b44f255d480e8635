"""Every number of a design document checked before it is used: a finite number (not a string, not a
boolean, not null where a number is needed), of the right sign, and every matrix of the shape the
document's own ``dims`` imply. Each failure is a :class:`~fte_casadi.errors.DesignFileError` naming
the key, e.g. ``'theta' must be a finite number >= 0; got -1``.
"""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import numpy as np

from .._labels import label_problem
from ..errors import DesignFileError
from ..ts import VERTEX_CHOICES

__all__ = []  # public: docs/api.md

_REMAKE = "make it again with `fte design PLANT -o FILE`"

#: the largest file read as a design document: fte's are kilobytes to a few megabytes (a 24-state design of
#: 4 rules, or 64 rules of 6 states: under 1 MB); reading JSON takes about 5 times its size in memory
MAX_DOCUMENT_BYTES = 64 * 2**20


def _reject_constant(name: str):
    raise DesignFileError(f"the design document holds {name}; every number must be finite")


def _one_value_per_key(pairs: list) -> dict:
    seen: set[str] = set()
    for key, _ in pairs:
        if key in seen:
            raise DesignFileError(
                f"the design document holds the key {key!r} twice in one JSON object (which of the two would be "
                "used is a guess: a document is data with one value per key); make it again with `fte design`"
            )
        seen.add(key)
    return dict(pairs)


def read_document(path: str | os.PathLike) -> dict:
    """The JSON of the design document at ``path``, or :class:`DesignFileError` saying what it is instead: a
    directory, a missing file, a file too large to be a design document (before it is read), a MAT file, not
    text, not JSON (truncated or corrupt), nested too deeply, a key twice in one object, or a NaN/Infinity."""
    p = Path(path)
    name = f"design file {str(p)!r}"
    if p.is_dir():
        raise DesignFileError(f"{name} is a directory; give the design document itself (the JSON file "
                              f"`fte design PLANT -o FILE.json` writes)")  # fmt: skip
    if not p.is_file():
        raise DesignFileError(f"{name} does not exist; make one with `fte design PLANT -o {p}`")
    size = p.stat().st_size
    if size > MAX_DOCUMENT_BYTES:
        raise DesignFileError(
            f"{name} is {size / 2**20:.0f} MB, more than the {MAX_DOCUMENT_BYTES / 2**20:.0f} MB a design "
            "document fte reads may be (fte's are a few MB at most): it is not read. Make it again with `fte design`"
        )
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise DesignFileError(f"{name} cannot be read: {exc.strerror or exc}") from None
    if data.startswith(b"MATLAB 5.0 MAT-file") or p.suffix.lower() == ".mat":
        raise DesignFileError(f"{name} is a MAT file (`fte design -o FILE.mat` writes one for MATLAB); fte reads "
                              "a design document as JSON: give the .json one (`fte design PLANT -o FILE.json`)")  # fmt: skip
    try:
        return json.loads(
            data.decode("utf-8"), parse_constant=_reject_constant, object_pairs_hook=_one_value_per_key
        )
    except DesignFileError as exc:
        raise DesignFileError(f"{name}: {exc}") from None
    except json.JSONDecodeError as exc:
        raise DesignFileError(
            f"{name} is not valid JSON (truncated or corrupt: {exc.msg} at line {exc.lineno}); "
            "make it again with `fte design`"
        ) from None
    except UnicodeDecodeError:
        raise DesignFileError(f"{name} is not a text file, so no design document (fte writes them as JSON); give "
                              "the JSON document `fte design PLANT -o FILE.json` writes") from None  # fmt: skip
    except RecursionError:
        raise DesignFileError(
            f"{name} nests its JSON too deeply to be a design document (fte writes matrices as "
            "lists of rows, three levels deep); make it again with `fte design`"
        ) from None


def _fail(source: str, key: str, what: str) -> DesignFileError:
    return DesignFileError(f"{source}: {key!r} {what}; {_REMAKE}")


#: the largest design parameter (gamma, sigma, delta, ...) a document or an option may give: the certificate
#: squares the parameters and multiplies them by the design's matrices, and the step multiplies the sliding gain
#: by its state, so a larger one overflows a double (gamma = 1e160 gave gamma**2 = inf)
PARAM_MAX = 1e100


def param_problem(value) -> str:
    """What makes ``value`` no design parameter ('' when it is one): a finite number, positive, at most
    :data:`PARAM_MAX`."""
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
        return f"must be a finite number; got {value!r}"
    if value > PARAM_MAX:
        return (f"must be at most {PARAM_MAX:g} (the certificate squares it: a larger one overflows a double); "
                f"got {value!r}")  # fmt: skip
    return ""


def _number(source: str, key: str, v, *, low=None, strict=False, integer=False, optional=False, high=None):
    """A finite JSON number (int or float, not bool), optionally >= / > ``low`` and <= ``high``."""
    if v is None and optional:
        return None
    kind = "an integer" if integer else "a finite number"
    bound = "" if low is None else f" {'>' if strict else '>='} {low:g}"
    bound += "" if high is None else f"{' and' if bound else ''} <= {high:g}"
    ok = not isinstance(v, bool) and isinstance(v, int if integer else (int, float))
    if ok and not integer:
        ok = math.isfinite(v)
    if ok and low is not None:
        ok = v > low if strict else v >= low
    if ok and high is not None:
        ok = v <= high
    if not ok:
        raise _fail(source, key, f"must be {kind}{bound}; got {v!r}")
    return v


def _leaves_numeric(v, depth: int = 0) -> bool:
    if isinstance(v, list):
        return depth < 4 and all(_leaves_numeric(e, depth + 1) for e in v)
    return not isinstance(v, bool) and isinstance(v, (int, float))


def _matrix(source: str, key: str, v, shape: tuple[int, ...]) -> np.ndarray:
    """A list of rows (or a vector for a 1-tuple ``shape``) of finite numbers, of exactly ``shape``."""
    if not isinstance(v, list) or not _leaves_numeric(v):
        raise _fail(source, key, "holds a NaN, null or other non-number entry (a string such as \"inf\", a boolean, "
                    "or a deeper list): it must be a matrix (a list of rows) of finite numbers")  # fmt: skip
    try:
        a = np.array(v, dtype=float)
    except ValueError:
        raise _fail(source, key, "has rows of different lengths") from None
    if len(shape) == 2 and a.size == 0 and 0 in shape:
        a = a.reshape(shape)  # [] or [[], ...] for a matrix with no columns or rows
    if a.shape != tuple(shape):
        want = " x ".join(map(str, shape))
        got = " x ".join(map(str, a.shape)) or "a number"
        raise _fail(source, key, f"must be {want} (from the document's dims); got {got}")
    if not np.all(np.isfinite(a)):
        raise _fail(source, key, "holds an infinite entry (a number too large for a double, e.g. 1e400)")
    return a


def _matrices(source: str, key: str, v, count: int, shape) -> None:
    if not isinstance(v, list) or len(v) != count:
        raise _fail(source, key, f"must be a list of {count} matrices (one per rule)")
    for i, M in enumerate(v):
        _matrix(source, f"{key}[{i}]", M, shape)


_DIMS = ("n", "m", "p", "ld", "lf", "r", "nbar")
_PARAMS = {
    "gamma": (0, True),
    "gamma1": (0, True),
    "sigma": (0, True),
    "delta": (0, False),
    "epsilon": (0, False),
}
_OPTIONAL_PARAMS = {
    "gamma2": (0, True),
    "kappa": (0, True),
    "boundary_layer": (0, True),
    "bound_weight": (0, False),
    "beta": (0, False),
}
_OBSERVER = {"sample_time": (0, True), "alpha": (0, False), "alpha_max": (0, False), "alpha_max_upper": (0, False),
             "ts_max": (0, False), "bound_weight": (0, False), "bound_objective_before": (None, False),
             "bound_objective_unweighted": (None, False),
             "bound_objective": (None, False)}  # fmt: skip


def check_document(doc: dict, source: str) -> None:
    """Raise :class:`DesignFileError` naming the first key of ``doc`` that is not a finite number of the
    right type, sign and shape. ``doc`` has every required key (checked before)."""
    dims = doc["dims"]
    d = {k: _number(source, f"dims.{k}", dims.get(k), low=0, integer=True) for k in _DIMS}
    for k in ("n", "m", "p", "lf", "r"):
        if d[k] < 1:
            raise _fail(source, f"dims.{k}", f"must be at least 1; got {d[k]}")
    if d["nbar"] != d["n"] + 2 * d["lf"]:
        raise _fail(source, "dims.nbar", f"must be n + 2 lf = {d['n'] + 2 * d['lf']}; got {d['nbar']}")
    if max(d.values()) > 10_000:
        raise _fail(source, "dims", f"holds a size above 10000 ({max(d.values())}): not a design fte makes")
    n, m, p, ld, lf, r, nbar = (d[k] for k in _DIMS)
    params = doc["params"]
    for k, (low, strict) in _PARAMS.items():
        _number(source, f"params.{k}", params.get(k), low=low, strict=strict, high=PARAM_MAX)
    for k, (low, strict) in _OPTIONAL_PARAMS.items():
        if k in params:
            _number(source, f"params.{k}", params[k], low=low, strict=strict, optional=True, high=PARAM_MAX)
    observer = doc.get("observer") or {}
    if not isinstance(observer, dict):
        raise _fail(source, "observer", "must be a JSON object")
    for k, (low, strict) in _OBSERVER.items():
        if k in observer:
            _number(source, f"observer.{k}", observer[k], low=low, strict=strict, optional=True)
    _number(source, "theta", doc["theta"], low=0, high=PARAM_MAX)
    r5 = doc.get("remark5") or {}
    if not isinstance(r5, dict):
        raise _fail(source, "remark5", "must be a JSON object")
    k5 = 0
    if r5.get("used"):
        bdu = r5.get("Bdu")
        if not isinstance(bdu, list) or not bdu or not isinstance(bdu[0], list):
            raise _fail(source, "remark5.Bdu", f"must be an {nbar} x k matrix")
        k5 = len(bdu[0])
        _matrix(source, "remark5.Bdu", bdu, (nbar, k5))
        _matrix(source, "remark5.gain", r5.get("gain"), (k5,))
    ls = doc["Ls"]
    if not k5 and isinstance(ls, list) and ls and isinstance(ls[0], list) and len(ls[0]) > lf:
        raise _fail(source, "Ls", f"has {len(ls[0]) - lf} more columns than faults but 'remark5' is not used")
    ns = lf + k5
    shapes = {"C": (p, n), "Df": (p, lf), "H": (nbar, p), "T": (nbar, nbar), "X": (n, n), "P": (n, n),
              "Kf": (m, lf), "Pbar": (nbar, nbar), "N": (ns, p), "Ls": (nbar, ns)}  # fmt: skip
    for k, shape in shapes.items():
        _matrix(source, k, doc[k], shape)
    lists = {"K": (m, n), "Q": (nbar, p), "L1": (nbar, p), "L2": (nbar, p), "R": (nbar, nbar)}
    for k, shape in lists.items():
        _matrices(source, k, doc[k], r, shape)
    if doc.get("Kf_rules") is not None:
        _matrices(source, "Kf_rules", doc["Kf_rules"], r, (m, lf))
    _matrix(source, "u_ref", doc["u_ref"], (m,))
    for k in ("x_ref", "x0"):
        if doc.get(k) is not None:
            _matrix(source, k, doc[k], (n,))
    lms = doc["local_models"]
    if not isinstance(lms, list) or len(lms) != r:
        raise _fail(source, "local_models", f"must hold r = {r} models")
    lm_shapes = {"A": (n, n), "B": (n, m), "Bd": (n, ld), "Bf": (n, lf), "W": (n, n), "a": (n,), "G": (n, m),
                 "Gf": (n, lf)}  # fmt: skip
    for i, lm in enumerate(lms):
        if not isinstance(lm, dict):
            raise _fail(
                source, f"local_models[{i}]", "must be a JSON object of matrices (A, B, Bd, Bf, W, ...)"
            )
        for k, shape in lm_shapes.items():
            if k in lm:
                _matrix(source, f"local_models[{i}].{k}", lm[k], shape)
        if "M" in lm:
            M = lm["M"]
            cols = len(M[0]) if isinstance(M, list) and M and isinstance(M[0], list) else 0
            _matrix(source, f"local_models[{i}].M", M, (n, cols))
    if not isinstance(doc["premises"], list):
        raise _fail(source, "premises", "must be a list")
    for i, pr in enumerate(doc["premises"]):
        if not isinstance(pr, dict):
            raise _fail(source, f"premises[{i}]", "must be a JSON object")
        lo = _number(source, f"premises[{i}].min", pr.get("min"))
        _number(source, f"premises[{i}].max", pr.get("max"), low=lo)
    for key in ("checks", "timings"):
        if not isinstance(doc[key], dict):
            raise _fail(source, key, "must be a JSON object")
    for k, v in doc["timings"].items():
        _number(source, f"timings.{k}", v, low=0)
    if "certified" in doc and not isinstance(doc["certified"], bool):
        raise _fail(source, "certified", f"must be true or false; got {doc['certified']!r}")
    schema = doc.get("schema", 1)
    if isinstance(schema, bool) or not isinstance(schema, int) or schema < 1:
        raise _fail(source, "schema", f"must be a positive integer; got {schema!r}")
    ph = doc.get("plant_hash", {})
    if not isinstance(ph, dict) or not all(isinstance(k, str) and isinstance(v, str) for k, v in ph.items()):
        raise _fail(source, "plant_hash", "must be a JSON object of hexadecimal strings")
    for k in ("plant", "plant_spec", "variant", "solver"):
        if k in doc and not isinstance(doc[k], str):
            raise _fail(source, k, f"must be a string; got {doc[k]!r}")
    _labels(source, doc, d)
    if doc.get("vertices") is not None and doc["vertices"] not in VERTEX_CHOICES:
        raise _fail(
            source, "vertices", f"must be one of {', '.join(VERTEX_CHOICES)} or null; got {doc['vertices']!r}"
        )


#: the lists of ``names`` and the size each has (from ``dims``); units may be empty strings
_NAME_LISTS = {"states": "n", "inputs": "m", "outputs": "p", "faults": "lf", "unknown_inputs": "ld",
               "state_units": "n", "input_units": "m", "output_units": "p"}  # fmt: skip


def _label(source: str, key: str, v, empty: bool = False) -> None:
    why = label_problem(v, empty=empty)
    if why:
        raise _fail(source, key, f"{why}: names and units are plain labels (printable text on one line, without "
                    "'/*', '*/', '//', '??', a backslash or a backquote); a document is data, never code")  # fmt: skip


def _labels(source: str, doc: dict, dims: dict) -> None:
    """Every name a document carries that is written into the generated C, README, FMU or MAT file is a plain
    label (:func:`fte_casadi._labels.label_problem`), and ``names``' lists have the lengths ``dims`` gives."""
    _label(source, "plant", doc["plant"])
    names = doc.get("names", {})
    if not isinstance(names, dict):
        raise _fail(source, "names", "must be a JSON object of lists of names")
    for k, v in names.items():
        if k in _NAME_LISTS:
            want = dims[_NAME_LISTS[k]]
            if not isinstance(v, list) or len(v) != want:
                raise _fail(source, f"names.{k}", f"must be a list of {want} names (dims.{_NAME_LISTS[k]})")
            for i, t in enumerate(v):
                _label(source, f"names.{k}[{i}]", t, empty=k.endswith("_units"))
        elif isinstance(v, str):
            _label(source, f"names.{k}", v, empty=True)
        elif isinstance(v, list):
            for i, t in enumerate(v):
                _label(source, f"names.{k}[{i}]", t, empty=True)
        else:
            raise _fail(source, f"names.{k}", "must be a name or a list of names")
    r5 = doc.get("remark5") or {}
    for i, t in enumerate(r5.get("unknown_inputs") or [] if isinstance(r5, dict) else []):
        _label(source, f"remark5.unknown_inputs[{i}]", t)
