"""Export the discrete observer/controller step of a design as self-contained embedded C.

CasADi's :class:`casadi.CodeGenerator` writes the maths of :func:`fte_casadi.step.step_function`
(the single source of truth that the simulator uses too) into ``fte_NAME_casadi.c``/``.h``;
:mod:`fte_casadi.codegen._template` fills the template files of ``codegen/templates/``: the
human-facing wrapper ``fte_NAME.h``/``.c`` of docs/interface.md and a README. What the CasADi output is made to satisfy, and how:

- no heap, no static mutable data: an ``SX`` Function is generated as straight-line code on
  scalar locals (``casadi_real a0, a1, ...``); the only statics are ``const`` sparsity tables.
  The work sizes CasADi reports (``*_SZ_IW``, ``*_SZ_W``) become arrays of the state struct.
- no I/O: ``verbose``, ``verbose_runtime``, ``main``, ``mex``, ``with_mem`` and ``with_export``
  are off, so ``stdio.h`` is never included (checked after generation: a hit raises).
- ``-Wall -Wextra -Werror -pedantic``: CasADi's entry points keep parameters they do not use
  (``iw``, ``w``, ``mem``); a ``(void)name;`` line is added for each, nothing else is changed.
- deterministic: no timestamps, CasADi prints constants with 17 significant digits.

Default sample time (when ``sample_time`` is not given): the sample time the design was made for
(``observer.sample_time``: the plant's scenario step, the step ``fte simulate`` runs), so that the C
runs the very step the simulator ran; for a design without one, ``0.1 * ts_max`` rounded down to
1, 2 or 5 times a power of ten, and for a built-in plant at most the time step its paper scenario
is simulated with (manipulator 1 ms, three-tank 10 ms). ``ts_max`` is the design's largest stable observer sample time
(``design.checks["ts_max"]``); a tenth of it keeps ``|Ts lambda|`` of the fastest observer mode
near 0.2, so the discrete observer follows the continuous one closely.
"""

from __future__ import annotations

import hashlib
import math
import os
import re
import tempfile
import textwrap
from pathlib import Path

import casadi as ca
import numpy as np

from .._atomic import write_set
from .._labels import c_comment, markdown
from .._rounding import series_floor
from .._version import VERSION
from ..design import Design
from ..errors import CodegenError, ParameterError
from ..step import step_function
from . import _template as template
from ._ranges import Y_FALLBACK, Y_FAULT_MARGIN, Y_MARGIN, initial_range, output_range

__all__ = ["generate_c", "default_sample_time", "output_files"]  # public: docs/api.md

#: directory name under ``generated/`` of each built-in plant
BUILTIN_DIRS = {"manipulator": "manipulator", "three-tank": "three_tank", "quadruple-tank": "quadruple_tank"}

_REALS = ("double", "float")
#: the version of fte_casadi a generated file names (left out of the set's number: a source checkout and an
#: installed package make the same files)
_FTE_VERSION = re.compile(r"fte_casadi \S+")
_REAL_BYTES = {"double": 8, "float": 4}
_FORBIDDEN = ("stdio.h", "printf", "fopen", "malloc", "calloc", "realloc", "free(")


def _version() -> str:
    """The package's version (:data:`fte_casadi._version.VERSION`), as the generated files say it."""
    return VERSION


def c_name(plant: str) -> str:
    """C identifier part for a plant name (``three-tank`` -> ``three_tank``; ``pendül`` -> ``pendul``: C99
    identifiers are ASCII letters, digits and ``_``, so accents are dropped and other characters become ``_``,
    never two in a row nor at either end: CasADi refuses a function name such as ``fte_a__casadi_step``)."""
    import unicodedata

    plain = unicodedata.normalize("NFKD", plant).encode("ascii", "ignore").decode()
    out = "".join(ch if (ch.isascii() and (ch.isalnum() or ch == "_")) else "_" for ch in plain)
    out = re.sub(r"_+", "_", out).strip("_")
    if not out:
        return "p"
    return "p_" + out if out[0].isdigit() else out


def output_files(plant: str) -> list[str]:
    """The fixed list of file names :func:`generate_c` writes for ``plant``."""
    nm = c_name(plant)
    return [f"fte_{nm}.h", f"fte_{nm}.c", f"fte_{nm}_casadi.h", f"fte_{nm}_casadi.c", "README.md"]


def _ts_max(design: Design) -> float:
    """The design's largest stable observer sample time (``checks["ts_max"]``), checked."""
    ts_max = design.checks.get("ts_max") if isinstance(design.checks, dict) else None
    try:
        ts_max = float(ts_max)
    except (TypeError, ValueError):
        ts_max = float("nan")
    if not (math.isfinite(ts_max) and ts_max > 0):
        raise CodegenError(
            f"the design gives no usable largest sample time (checks.ts_max = {design.checks.get('ts_max')!r}); "
            "its observer may be unstable in discrete time: make the design again with `fte design`"
        )
    return ts_max


def default_sample_time(design: Design, scenario_step: float | None = None) -> float:
    """Default sample time: the sample time the design was made for (``observer.sample_time``, the
    scenario's step, which ``fte simulate`` runs and the default alpha respects) when it is below
    ``ts_max``; otherwise ``0.1 * ts_max`` rounded down to 1, 2 or 5 times a power of ten, and no
    more than ``scenario_step`` when the caller knows the plant's scenario (``Scenario.dt``; the CLI
    passes the built-in plants' :data:`fte_casadi.plants.SCENARIOS` step)."""
    st = design.observer.sample_time
    if st is not None and math.isfinite(float(st)) and 0 < float(st) < _ts_max(design):
        return float(st)
    sample_time = series_floor(0.1 * _ts_max(design))
    return sample_time if scenario_step is None else min(sample_time, float(scenario_step))


def _check_sample_time(design: Design, sample_time) -> float:
    """``sample_time`` as a float below ``ts_max`` (the CLI's ``--sample-time``); None: :func:`default_sample_time`."""
    ts_max = _ts_max(design)
    if sample_time is None:
        return default_sample_time(design)
    given = sample_time
    try:
        sample_time = float(given)
    except (TypeError, ValueError):
        raise ParameterError(f"sample time --sample-time must be a number; got {given!r}") from None
    if not (math.isfinite(sample_time) and sample_time > 0):
        raise ParameterError(
            f"sample time --sample-time must be positive and finite; got {given!r} (the design allows Ts < {ts_max:.6g})"
        )
    if sample_time >= ts_max:
        raise ParameterError(
            f"sample time Ts = {sample_time:.6g} is not below the design's ts_max = {ts_max:.6g}: the discrete "
            f"observer would be unstable; choose --sample-time below {ts_max:.6g} (default {default_sample_time(design):.6g})"
        )
    return sample_time


_FUNC_RE = re.compile(r"^(?:static )?[A-Za-z_][\w \*]*?\b(\w+)\(([^()]*)\) \{\n", re.M)


def _void_unused(src: str) -> str:
    """Add ``(void)p;`` for each parameter a generated function body does not use."""
    out = []
    pos = 0
    for mt in _FUNC_RE.finditer(src):
        end = src.find("\n}\n", mt.end())
        body = src[mt.end() : end + 1]
        params = [p.strip() for p in mt.group(2).split(",") if p.strip() and p.strip() != "void"]
        unused = []
        for p in params:
            pname = re.findall(r"\w+", p)[-1]
            if not re.search(rf"\b{pname}\b", body):
                unused.append(pname)
        out.append(src[pos : mt.end()])
        out.extend(f"  (void){p};\n" for p in unused)
        pos = mt.end()
    out.append(src[pos:])
    return "".join(out)


def _casadi_sources(fn: ca.Function, name: str, real: str) -> tuple[str, str]:
    opts = {
        "with_header": True,
        "prefix": f"fte_{name}_cs",
        "casadi_real": real,
        "casadi_int": "int",
        "with_mem": False,
        "with_export": False,
        "with_import": False,
        "verbose": False,
        "verbose_runtime": False,
        "main": False,
        "mex": False,
        "cpp": False,
        "codegen_scalars": False,
        "include_math": True,
    }
    base = f"fte_{name}_casadi"
    with tempfile.TemporaryDirectory(prefix="fte_codegen_") as tmp:
        gen = ca.CodeGenerator(f"{base}.c", opts)
        gen.add(fn)
        gen.generate(tmp + os.sep)
        c_src = Path(tmp, f"{base}.c").read_text()
        h_src = Path(tmp, f"{base}.h").read_text()
    c_src = _void_unused(c_src)
    if real == "float":
        c_src = single_precision(c_src)
    c_src = c_src.replace("#include <math.h>\n", f'#include <math.h>\n#include "{base}.h"\n', 1)
    for text in (c_src, h_src):
        low = text.lower()
        hits = [w for w in _FORBIDDEN if w in low]
        if hits:
            raise CodegenError(
                f"CasADi's generated code contains {hits}; this CasADi version cannot be used for embedded C"
            )
    return c_src, h_src


#: the <math.h> functions CasADi may call; with ``--real float`` each becomes its float version (sinf...)
_MATH = ("sin", "cos", "tan", "asin", "acos", "atan", "atan2", "sinh", "cosh", "tanh", "asinh", "acosh",
         "atanh", "exp", "expm1", "log", "log1p", "log10", "log2", "sqrt", "cbrt", "pow", "fabs", "fmax",
         "fmin", "fmod", "floor", "ceil", "round", "trunc", "erf", "erfc", "copysign", "hypot", "remainder",
         "lgamma", "tgamma")  # fmt: skip
_MATH_RE = re.compile(r"\b(" + "|".join(_MATH) + r")\(")
#: a decimal floating literal that is not part of a name or of a longer number (CasADi writes ``1.``,
#: ``6.``, ``1.0000000000000000e-03``); integers (sparsity tables, ``? ... : 0``) are left alone
_REAL_LITERAL_RE = re.compile(r"(?<![\w.])(\d+\.\d*(?:[eE][-+]?\d+)?|\d+[eE][-+]?\d+)(?![\w.])")


def single_precision(c_src: str) -> str:
    """CasADi's C made float throughout: ``sinf``/``fabsf``/``sqrtf``... and ``f``-suffixed literals.

    CasADi's ``casadi_real`` option changes the type only: the maths still calls the double functions
    and writes double literals, so every operation would be promoted to double and rounded back
    (``-Wdouble-promotion`` warns on each). Code lines only; comments and preprocessor lines are kept.
    """
    out = []
    for line in c_src.splitlines(keepends=True):
        head = line.lstrip()
        if head.startswith(("#", "/*", "*")):
            out.append(line)
            continue
        line = _MATH_RE.sub(lambda mt: mt.group(1) + "f(", line)
        out.append(_REAL_LITERAL_RE.sub(lambda mt: mt.group(1) + "f", line))
    return "".join(out)


def _sizes(h_src: str, fname: str) -> dict:
    out = {}
    for key in ("SZ_ARG", "SZ_RES", "SZ_IW", "SZ_W"):
        mt = re.search(rf"#define {fname}_{key} (\d+)", h_src)
        if mt is None:
            raise CodegenError(
                f"CasADi's header lacks {fname}_{key}; unsupported CasADi version {ca.__version__}"
            )
        out[key] = int(mt.group(1))
    return out


def _memory(c_src: str, real: str, nxbar: int, sizes: dict, latches: int = 0) -> dict:
    rb = _REAL_BYTES[real]
    literals = len(re.findall(r"^\s*a\d+=[-+]?[0-9][0-9.eE+-]*;$", c_src, re.M))
    sparsity = sum(int(k) for k in re.findall(r"static const casadi_int \w+\[(\d+)\]", c_src))
    decl = re.findall(r"^\s*casadi_real (a\d+(?:, a\d+)*);$", c_src, re.M)
    local_count = sum(len(d.split(",")) for d in decl)
    state = 2 * nxbar * rb + sizes["SZ_W"] * rb + sizes["SZ_IW"] * 4
    detail = f"z and z_next, {nxbar} `{real}` each"
    if latches:
        detail += f" (z ends with the {latches} latches of the accommodation gate)"
    if sizes["SZ_W"]:
        detail += f"; w, {sizes['SZ_W']} `{real}`"
    if sizes["SZ_IW"]:
        detail += f"; iw, {sizes['SZ_IW']} `int`"
    return {
        "state_bytes": state,
        "state_detail": detail,
        "const_values": literals,
        "const_bytes": literals * rb,
        "sparsity_ints": sparsity,
        "sparsity_bytes": 4 * sparsity,
        "locals": local_count,
        "locals_bytes": local_count * rb,
        "pointer_count": sizes["SZ_ARG"] + sizes["SZ_RES"],
    }


def _fmt(v: float, real: str = "double") -> str:
    literal = repr(float(v))
    if real == "float":
        literal += "" if ("." in literal or "e" in literal) else ".0"
        return literal + "f"
    return literal


def _c_values(values, real: str = "double") -> str:
    """Numbers as a C initialiser list, 17 significant digits, four to a line (``f``-suffixed in float)."""
    items = [_fmt(float(v), real) for v in values]
    return ",\n".join("  " + ", ".join(items[k : k + 4]) for k in range(0, len(items), 4))


def _wrapper(
    design: Design,
    name: str,
    real: str,
    sample_time: float,
    ts_max: float,
    boundary_layer,
    c_src: str,
    h_src: str,
    y_range: dict,
    init_range: dict,
    set_id: str = "0UL",
):
    fname = f"fte_{name}_casadi_step"
    sizes = _sizes(h_src, fname)
    dims = design.dims
    n, m, p, lf, nbar = (int(v) for v in (dims.n, dims.m, dims.p, dims.lf, dims.nbar))
    names = design.names or {}

    def labels(esc) -> dict:
        """The texts that carry the plant's names and units, each name escaped by ``esc`` (a document's names
        are data: escaped for C comments in the C, for Markdown in the README; fte_casadi._labels)."""

        def joined(key, count, stem):
            v = names.get(key) or [f"{stem}{k}" for k in range(count)]
            return ", ".join(esc(t) for t in v)

        return {
            "plant": esc(design.plant),
            "time_unit": esc(names.get("time_unit", "s")),
            "y_names": joined("outputs", p, "y"),
            "u_names": joined("inputs", m, "u"),
            "x_names": joined("states", n, "x"),
            "f_names": joined("faults", lf, "f"),
            "y_range_text": _range_text(design, y_range, real, esc),
            "saturation_text": _saturation_text(design, esc),
            **_sliding_text(design, esc),
        }

    NAME = name.upper()
    work_fields = ""
    gate = _gate_texts(design, NAME)
    work_init = gate.pop("gate_init")
    if sizes["SZ_W"]:
        work_fields += f"  fte_real w[{sizes['SZ_W']}];     /* CasADi real work array */\n"
        work_init += f"  for (i = 0; i < {sizes['SZ_W']}; ++i) s->w[i] = (fte_real)0;\n"
    if sizes["SZ_IW"]:
        work_fields += f"  int iw[{sizes['SZ_IW']}];     /* CasADi integer work array */\n"
        work_init += f"  for (i = 0; i < {sizes['SZ_IW']}; ++i) s->iw[i] = 0;\n"
    setup = ["arg[0] = s->z;", "arg[1] = y;"]
    setup += [f"arg[{k}] = 0;" for k in range(2, sizes["SZ_ARG"])]
    setup += [
        "res[0] = s->z_next;",
        "res[1] = u;",
        "res[2] = xbarhat;",
        "res[3] = yc;",
        "res[4] = 0; /* s: not exported */",
    ]
    setup += [f"res[{k}] = 0;" for k in range(5, sizes["SZ_RES"])]
    mem = _memory(c_src, real, design.nz, sizes, lf if design.latched else 0)
    certified = "certified" if design.certified else "NOT CERTIFIED (no guarantee: see the design's status)"
    affine = any(np.any(lm.a) for lm in design.local_models)
    sub = {
        "name": name,
        "NAME": NAME,
        "version": _version(),
        "variant": design.variant,
        "certified": certified,
        "real": real,
        "ny": p,
        "nu": m,
        "nxbar": nbar,
        "n": n,
        "lf": lf,
        "sample_time_c": f"({_fmt(sample_time, real)})",
        "bits": "uint64_t" if real == "double" else "uint32_t",
        "exp_mask": "UINT64_C(0x7FF0000000000000)" if real == "double" else "UINT32_C(0x7F800000)",
        "ymin_values": _c_values(y_range["lo"], real),
        "ymax_values": _c_values(y_range["hi"], real),
        "y_margin_text": f"{Y_MARGIN:g}",
        "y_fault_margin_text": f"{Y_FAULT_MARGIN:g}",
        "sample_time_text": _fmt(sample_time),
        "ts_max_text": f"{ts_max:.6g}",
        "work_fields": work_fields,
        **gate,
        "work_init": work_init,
        "sz_arg": sizes["SZ_ARG"],
        "sz_res": sizes["SZ_RES"],
        "arg_setup": "".join(f"  {t}\n" for t in setup),
        "casadi_fn": fname,
        "iw_arg": "s->iw" if sizes["SZ_IW"] else "0",
        "w_arg": "s->w" if sizes["SZ_W"] else "0",
        "sliding": "sgn(s)" if boundary_layer is None else f"sat(s / {_fmt(boundary_layer)})",
        "affine": " + T abar_i" if affine else "",
        "u_ref": "[" + ", ".join(f"{v:.17g}" for v in np.ravel(design.u_ref)) + "]",
        "H_values": _c_values(np.asarray(design.H, dtype=float).ravel(), real),
        "xbar0_values": _c_values(design.xbar0, real),
        "xbar0_min_values": _c_values(init_range["xbar_lo"], real),
        "xbar0_max_values": _c_values(init_range["xbar_hi"], real),
        "z_min_values": _c_values(init_range["z_lo"], real),
        "z_max_values": _c_values(init_range["z_hi"], real),
        "fallback_text": f"{Y_FALLBACK[real]:.0e}",
        "set_id": set_id,
        "x0_text": ", ".join(_fmt(v) for v in design.xbar0[:n]),
        **mem,
    }
    files = output_files(design.plant)
    table = {
        files[0]: "types, sizes and the two calls (include this one)",
        files[1]: "the wrapper: input check, state update",
        files[2]: "CasADi's declarations of the generated step",
        files[3]: "the maths, written by CasADi's CodeGenerator",
        files[4]: "this file",
    }
    sub["file_table"] = "\n".join(f"| `{k}` | {v} |" for k, v in table.items())
    in_c, in_md = {**sub, **labels(c_comment)}, {**sub, **labels(markdown)}
    return {
        files[0]: template.fill(template.TEMPLATES["header"], in_c),
        files[1]: template.fill(template.TEMPLATES["source"], in_c),
        files[4]: template.fill(template.TEMPLATES["readme"], in_md),
    }, mem


def _gate_texts(design: Design, NAME: str) -> dict:
    """The template's texts for the accommodation gate: nothing without one (the C is then byte for byte
    what it was); for a latched gate (a release ratio below 1) its latches, stored after z in the state."""
    acc = design.accommodation
    out = {"z_len": f"FTE_{NAME}_NXBAR", "z_gate_text": "", "gate_doc": "", "gate_init": "",
           "accommodation_text": ""}  # fmt: skip
    if acc is None:
        return out
    thr = ", ".join(f"{v:.6g}" for v in acc["thresholds"])
    if acc.get("rule") == "explain":
        ct = "; ".join(", ".join(f"{v:.4g}" for v in row) for row in acc["crosstalk"])
        rule = (f"fault j is compensated in u (the Kf fhat term) while |fhat_j| >= threshold_j + sum_q crosstalk[j][q] "
                f"|fhat_q| (thresholds {thr}; crosstalk rows {ct}), a fault no other one cross-talks into always")  # fmt: skip
        if design.remembers and "crosstalk_held" in acc:
            ch = "; ".join(", ".join(f"{v:.4g}" for v in row) for row in acc["crosstalk_held"])
            rule += (f"; each term the smaller of crosstalk[j][q] |fhat_q| and crosstalk_held[j][q] M_q, M_q the "
                     f"largest |fhat_q| held, decaying as the memories (crosstalk_held rows {ch})")  # fmt: skip
        if design.remembers:
            ov = ", ".join(f"{v:.4g}" for v in acc["overshoot"])
            rule += (f", and more than its own overshoot explains: + overshoot_j m_j (overshoot {ov}), m_j the "
                     f"largest estimate of the other sign, held and decaying by exp(-Ts / {acc['memory_time']:.6g})")  # fmt: skip
    else:
        rule = (f"fault j is compensated in u (the Kf fhat term) when |fhat_j| >= threshold_j and |fhat_j| / "
                f"threshold_j is the largest (thresholds {thr})")  # fmt: skip
    if acc.get("never"):
        names = list(design.names.get("faults") or [])
        off = ", ".join(names[j] if j < len(names) else f"fault {j}" for j in acc["never"])
        rule += f"; never compensated: {off} (its compensation measured worse than none in its own windows)"
    nf = f"FTE_{NAME}_NF"
    k = (1 if design.latched else 0) + (2 if design.remembers else 0)  # the state after z, in blocks of nf
    if k:
        out["z_len"] = f"FTE_{NAME}_NXBAR + {nf}" if k == 1 else f"FTE_{NAME}_NXBAR + {k} * {nf}"
        out["z_gate_text"] = (", then the gate's latches" if design.latched else "") + (
            (", then its memories" if design.latched else ", then the gate's memories")
            if design.remembers
            else ""
        )
        out["gate_init"] = (
            f"  for (i = FTE_{NAME}_NXBAR; i < {out['z_len']}; ++i) s->z[i] = s->z_next[i] = (fte_real)0;\n"
        )
    mem = (f"z[FTE_{NAME}_NXBAR{' + ' + nf if design.latched else ''} + j] and z[... + {nf} + j] hold fault j's "
           "largest positive and negative estimates, decaying (init and init_from_y set them to 0)")  # fmt: skip
    if not design.latched:
        if design.remembers:
            doc = f"Accommodation after detection: {rule}. {mem}."
            out["gate_doc"] = "\n/* " + "\n * ".join(textwrap.wrap(doc, 100)) + " */\n"
            out["accommodation_text"] = (
                f"\nAccommodation after detection: {rule}; its memories follow `z`: {mem}."
            )
        else:
            out["accommodation_text"] = (
                f"\nAccommodation after detection: {rule}, in each sample anew (no memory)."
            )
        return out
    rho = float(acc["release"])
    held = (f"and stays compensated while |fhat_j| / threshold_j >= {rho:g}, unless another fault switches on "
            "with a larger ratio")  # fmt: skip
    if acc.get("rule") == "explain":
        held = f"and stays compensated while that ratio >= {rho:g}"
    then = f" Then its memories: {mem}." if design.remembers else ""
    out["accommodation_text"] = (
        f"\nAccommodation after detection: {rule}, {held}. The latches (1: compensated in the last sample) follow "
        f"the observer state in `z`, from `z[FTE_{NAME}_NXBAR]` on; `init` and `init_from_y` set them to 0.{then}"
    )
    doc = (f"Accommodation after detection: {rule}, {held}. z[FTE_{NAME}_NXBAR + j] is fault j's latch (1: "
           "compensated in the last sample's u, 0: not); init and init_from_y set the latches to 0.")  # fmt: skip
    doc += f" {mem}." if design.remembers else ""
    out["gate_doc"] = "\n/* " + "\n * ".join(textwrap.wrap(doc, 100)) + " */\n"
    return out


def _sliding_text(design: Design, esc=str) -> dict:
    """The sliding variables' count and gains: ``(delta + eps)`` per fault, and with Remark 5 first the
    gains of the unknown inputs H does not decouple (their names escaped by ``esc``)."""
    lf = int(design.dims.lf)
    r5 = design.remark5 or {}
    if not r5.get("used"):
        return {"ns": lf, "ns_text": "", "sliding_gain": "(delta + eps)"}
    k = len(r5["gain"])
    names = ", ".join(esc(t) for t in r5.get("unknown_inputs", []))
    gains = ", ".join(f"{v:.6g}" for v in design.sliding_gain())
    return {
        "ns": lf + k,
        "ns_text": f": {k} for the unknown inputs H does not decouple ({names}; Remark 5), then {lf} for the faults",
        "sliding_gain": f"diag({gains}) (Remark 5: first the gains bounding the undecoupled {names})",
    }


def _saturation_text(design: Design, esc=str) -> str:
    """One line saying how u is clipped (the step applies it, and feeds the observer the clipped u); the
    inputs' names escaped by ``esc``."""
    if design.input_limits is None:
        return "none (u is not clipped)."
    names = (design.names or {}).get("inputs") or [f"u{k}" for k in range(int(design.dims.m))]

    def bound(v: float) -> str:
        return f"{v:.17g}".replace("inf", "infinity")  # the number only: a name may hold 'inf'

    parts = [
        f"{esc(nm)} in [{bound(lo)}, {bound(hi)}]"
        for nm, (lo, hi) in zip(names, np.asarray(design.input_limits, float))
    ]
    return "u is clipped to " + ", ".join(parts) + "; the observer is fed the clipped u."


def _range_text(design: Design, rng: dict, real: str, esc=str) -> str:
    """The line on the accepted range of y, the outputs' names escaped by ``esc``."""
    names = (design.names or {}).get("outputs") or [f"y{k}" for k in range(len(rng["lo"]))]
    parts = []
    for k, nm in enumerate(map(esc, names)):
        if rng["known"][k]:
            parts.append(f"{nm} in [{rng['lo'][k]:.6g}, {rng['hi'][k]:.6g}]")
        else:
            parts.append(f"|{nm}| <= {rng['hi'][k]:.0e} (range unknown)")
    return "; ".join(parts)


def prepare_dir(out_dir: Path) -> None:
    if out_dir.exists() and not out_dir.is_dir():
        raise CodegenError(
            f"output directory {str(out_dir)!r} exists and is not a directory; choose another --out"
        )
    try:
        out_dir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CodegenError(
            f"cannot create output directory {str(out_dir)!r}: {exc.strerror or exc}; choose a writable --out"
        ) from None
    if not os.access(out_dir, os.W_OK | os.X_OK):
        raise CodegenError(f"output directory {str(out_dir)!r} is not writable; choose a writable --out")


def file_mode() -> int:
    """``0o666`` less the process umask (what ``open`` would give; mkstemp gives 0o600)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return 0o666 & ~mask


def generate_c(
    design: Design | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    sample_time: float | None = None,
    real: str = "double",
    boundary_layer: float | None = None,
) -> list[Path]:
    """Write the embedded C of ``design``'s discrete step into ``out_dir``.

    Parameters
    ----------
    design : Design or path
        The design record, or the path of a design document (read with ``Design.load``).
    out_dir : path
        Created if needed. The files of :func:`output_files` are put in place as one set
        (:func:`fte_casadi._atomic.write_set`: the directory is swapped with a new one holding the new files
        and every other entry of the old one, carried over as hard links), so that a kill at any moment leaves
        the old set or the new one, never a mix; nothing else in the directory changes.
    sample_time : float, optional
        The step's sample time Ts (the CLI's ``--sample-time``); positive and below
        ``design.checks["ts_max"]``. Default :func:`default_sample_time`.
    real : {"double", "float"}
        The C type of ``fte_real``.
    boundary_layer : float, optional
        Replace ``sgn(s)`` by ``sat(s / phi)``; default the design's ``params.boundary_layer``
        when it has one (a design chosen by ``fte tune``), else ``sgn(s)``.

    Returns
    -------
    list of Path
        The files written, in the order of :func:`output_files`.

    Examples
    --------
    >>> import tempfile
    >>> from fte_casadi.plants import three_tank
    >>> from fte_casadi.ts import derive
    >>> from fte_casadi.design import design
    >>> d = design(derive(three_tank(), fidelity_samples=200))
    >>> [p.name for p in generate_c(d, tempfile.mkdtemp(), sample_time=0.1)][:2]
    ['fte_three_tank.h', 'fte_three_tank.c']
    """
    if isinstance(design, (str, os.PathLike)):
        design = Design.load(design)  # DesignFileError on a missing, truncated or corrupt file
    if not isinstance(design, Design):
        raise CodegenError(
            f"generate_c needs a Design record (Design.load(path)); got {type(design).__name__}"
        )
    if real not in _REALS:
        raise ParameterError(f"--real must be one of {list(_REALS)}; got {real!r}")
    sample_time = _check_sample_time(design, sample_time)
    if boundary_layer is None:  # the design's own (fte tune), as the simulation runs it
        boundary_layer = design.params.boundary_layer
    out = Path(out_dir)
    check_out(out)
    texts = c_texts(design, sample_time=sample_time, real=real, boundary_layer=boundary_layer)
    return write_c_set(out, {name: text.encode("utf-8") for name, text in texts.items()})


def write_c_set(out: Path, files: dict[str, bytes]) -> list[Path]:
    """Put the generated ``files`` into ``out`` as one set (:func:`fte_casadi._atomic.write_set`)."""
    try:
        return write_set(out, files)
    except ValueError:
        raise CodegenError(f"--out {out} is the current directory or holds it; fte codegen replaces its output "
                           "directory as one set: give a directory of its own, such as c/") from None  # fmt: skip
    except OSError as exc:
        raise CodegenError(
            f"cannot write the generated C into {str(out)!r}: {exc.strerror or exc}; choose a writable --out"
        ) from None


def c_texts(
    design: Design, *, sample_time: float, real: str = "double", boundary_layer=None
) -> dict[str, str]:
    """The files of :func:`generate_c` (name: text, in the order of :func:`output_files`) for ``design`` at the
    checked ``sample_time``. Each C file carries the set's number (``FTE_NAME_SET``, a hash of everything the
    files are made of): a ``.c`` file compiled with headers of another run of ``fte codegen`` stops the
    compilation with an ``#error``, so that a mix of two sets never builds."""
    ts_max = _ts_max(design)
    name = c_name(design.plant)
    if boundary_layer is None:  # the design's own (fte tune), as the simulation runs it
        boundary_layer = design.params.boundary_layer
    try:
        fn = step_function(
            design, sample_time, tolerant=True, boundary_layer=boundary_layer, name=f"fte_{name}_casadi_step"
        )
    except ParameterError:
        raise
    except Exception as exc:  # noqa: BLE001 - a CasADi failure on a malformed record
        raise CodegenError(
            f"cannot build the step of this design ({exc}); make the design again with `fte design`"
        ) from None
    c_src, h_src = _casadi_sources(fn, name, real)
    y_range = output_range(design, fn, real)
    try:
        init_range = initial_range(design, fn, y_range, real)
    except ValueError as exc:
        raise CodegenError(f"{exc}: the generated C would refuse its own nominal start; make the design again "
                           "for this plant (`fte design PLANT -o FILE`)") from None  # fmt: skip
    args = (design, name, real, sample_time, ts_max, boundary_layer, c_src, h_src, y_range, init_range)
    draft, _ = _wrapper(*args, "SET")  # the set's number: a hash of the files (fte's version left out)
    made_of = [c_src, h_src, *(_FTE_VERSION.sub("fte_casadi", t) for t in draft.values())]
    set_id = f"0x{hashlib.sha256(chr(0).join(made_of).encode('utf-8')).hexdigest()[:8]}UL"
    texts, _ = _wrapper(*args, set_id)
    NAME = name.upper()
    h_src = h_src.replace(
        " */\n", f" */\n#define FTE_{NAME}_CASADI_SET {set_id} /* the set these files belong to */\n", 1
    )
    c_src = c_src.replace(f'#include "fte_{name}_casadi.h"\n', f'#include "fte_{name}_casadi.h"\n'
                          f"#if FTE_{NAME}_CASADI_SET != {set_id}\n"
                          f'#error "fte_{name}_casadi.h is of another run of fte codegen than this file: generate '
                          'the C again as one set (fte codegen)"\n#endif\n', 1)  # fmt: skip
    files = output_files(design.plant)
    return {
        files[0]: texts[files[0]],
        files[1]: texts[files[1]],
        files[2]: h_src,
        files[3]: c_src,
        files[4]: texts[files[4]],
    }


def check_out(out: Path) -> None:
    """Refuse an output directory that is a file, or whose folder cannot be written into (before any work)."""
    if out.exists() and not out.is_dir():
        raise CodegenError(
            f"output directory {str(out)!r} exists and is not a directory; choose another --out"
        )
    near = out.absolute().parent
    while not near.exists():
        near = near.parent
    if not os.access(near, os.W_OK | os.X_OK):
        raise CodegenError(
            f"output directory {str(out)!r} is not writable (nor is {near}); choose a writable --out"
        )


def memory_report(design: Design, *, sample_time: float | None = None, real: str = "double") -> dict:
    """Bytes of state, constant data and stack of the generated step (as the README states them)."""
    sample_time = _check_sample_time(design, sample_time)
    name = c_name(design.plant)
    fn = step_function(design, sample_time, tolerant=True, name=f"fte_{name}_casadi_step")
    c_src, h_src = _casadi_sources(fn, name, real)
    lf = int(design.dims.lf) if design.latched else 0
    return _memory(c_src, real, design.nz, _sizes(h_src, f"fte_{name}_casadi_step"), lf)
