"""An FMI 2.0 co-simulation FMU of the discrete observer/controller step (``fte codegen ... --fmu``).

The FMU wraps exactly the C that :func:`~fte_casadi.codegen._generate.generate_c` writes (same
sample time, real type and boundary layer) in a small FMI wrapper
(the template ``codegen/templates/MID_fmi2.c.in``, :mod:`._template`), compiled for this platform with the system C
compiler. What it holds (a zip file, ``<model identifier>.fmu``)::

    modelDescription.xml                   FMI 2.0, <CoSimulation>, fixed step Ts
    binaries/<platform>/<id>.so            built here (linux64 .so, darwin64 .dylib)
    sources/fte_NAME*.c/.h                 the generated C, unchanged
    sources/<id>_fmi2.c                    the FMI wrapper
    sources/fte_fmi2.h                     declarations of the FMI 2.0 C API (ABI of the standard's)
    documentation/README.md                the generated C's README

Variables (in this order, value references 0, 1, ...), named after the plant's own names
(made C identifiers: characters other than letters, digits and ``_`` become ``_``)::

    inputs   y:        one per plant output, named as the plant names its outputs
    outputs  u:        one per plant input, named as the plant names its inputs
             xbarhat:  <state>_hat, then <fault>_dot_hat (fdothat), then <fault>_hat (fhat)
             yc:       <output>_c, the reliable (fault-compensated) outputs y - Df fhat
             gate:     <fault>_gate, only for a latched accommodation gate (a release ratio below 1):
                       1 while that fault is compensated in u (the sample's gate, also its latch)

A name already taken gets ``_2``, ``_3``, ... appended. The sampling semantics (where the first
measurement is taken, what an output read returns) are described in the wrapper's header
comment and in ``docs/fmu.md``.
"""

from __future__ import annotations

import hashlib
import os
import platform
import re
import sys
import tempfile
import uuid
import xml.etree.ElementTree as ET
import zipfile
from dataclasses import dataclass
from pathlib import Path

import casadi as ca
import numpy as np

from .._labels import c_comment, c_string, xml_text
from ..design import Design
from ..errors import CodegenError, ParameterError
from ..step import step_function
from . import _build as build
from . import _template as template
from ._generate import (
    _check_sample_time,
    _version,
    c_name,
    c_texts,
    check_out,
    output_files,
    prepare_dir,
    write_c_set,
)

__all__ = ["generate_fmu"]  # public: docs/api.md

_TOOL = "fte_casadi"
_ZIP_TIME = (1980, 1, 1, 0, 0, 0)  # fixed timestamps: the same design gives the same archive
#: file name of the FMI 2.0 declarations in the FMU's sources
FMI2_HEADER_NAME = template.TEMPLATES["fmi2_header"]


@dataclass(frozen=True)
class FmuVariable:
    """One scalar variable of the FMU: its name, value reference, role and documentation."""

    name: str
    value_reference: int
    causality: str  # "input" or "output"
    group: str  # "y", "u", "xbarhat", "yc" or "gate"
    index: int  # position inside its group's vector
    description: str
    unit: str | None = None
    start: float | None = None


def model_identifier(plant: str) -> str:
    """The FMU's model identifier (and file and library name): the plant name as a C identifier."""
    return c_name(plant)


def fmu_path(design: Design, out_dir: str | os.PathLike) -> Path:
    """``out_dir/<model identifier>.fmu``."""
    return Path(out_dir) / f"{model_identifier(design.plant)}.fmu"


def _ident(name: str) -> str:
    out = re.sub(r"[^A-Za-z0-9_]", "_", str(name))
    if not out or out[0].isdigit():
        out = "v_" + out
    return out


def _names(design: Design, key: str, count: int, stem: str) -> list[str]:
    given = list((design.names or {}).get(key) or [])
    if len(given) != count:
        given = [f"{stem}{k}" for k in range(count)]
    return [str(v) for v in given]


def _units(design: Design, key: str, count: int) -> list[str | None]:
    given = list((design.names or {}).get(key) or [])
    if len(given) != count:
        return [None] * count
    return [str(u) if isinstance(u, str) and u.strip() else None for u in given]


def fmu_variables(design: Design) -> list[FmuVariable]:
    """The FMU's variables in value-reference order: y, then u, xbarhat and yc (see the module text)."""
    n, m, p, lf = (int(v) for v in (design.dims.n, design.dims.m, design.dims.p, design.dims.lf))
    ys, us = _names(design, "outputs", p, "y"), _names(design, "inputs", m, "u")
    xs, fs = _names(design, "states", n, "x"), _names(design, "faults", lf, "f")
    y_units, x_units = _units(design, "output_units", p), _units(design, "state_units", n)
    u_units = _units(design, "input_units", m)
    y_start = np.asarray(design.C, float) @ design.xbar0[:n]
    limited = design.input_limits is not None
    rows = [
        ("input", "y", k, ys[k], f"measurement {ys[k]} (plant output {k + 1}), sampled at each step",
         y_units[k], float(y_start[k]))
        for k in range(p)
    ]  # fmt: skip
    rows += [
        ("output", "u", k, us[k], f"control input {us[k]} (plant input {k + 1})"
         + (", clipped to its actuator limits" if limited else ""), u_units[k], None)
        for k in range(m)
    ]  # fmt: skip
    rows += [("output", "xbarhat", k, f"{xs[k]}_hat", f"estimate of state {xs[k]}", x_units[k], None)
             for k in range(n)]  # fmt: skip
    rows += [("output", "xbarhat", n + k, f"{fs[k]}_dot_hat", f"estimate of the time derivative of fault {fs[k]}",
              None, None) for k in range(lf)]  # fmt: skip
    rows += [("output", "xbarhat", n + lf + k, f"{fs[k]}_hat", f"estimate of fault {fs[k]}", None, None)
             for k in range(lf)]  # fmt: skip
    rows += [("output", "yc", k, f"{ys[k]}_c", f"reliable output {ys[k]}: y - Df fhat", y_units[k], None)
             for k in range(p)]  # fmt: skip
    if design.latched:  # the accommodation gate's latches: 1 while fault k is compensated in u
        rows += [("output", "gate", k, f"{fs[k]}_gate", f"accommodation gate of fault {fs[k]}: 1 while it is "
                  "compensated in u (this sample), else 0", None, None) for k in range(lf)]  # fmt: skip
    taken: set[str] = set()
    out = []
    for vr, (causality, group, idx, name, desc, unit, start) in enumerate(rows):
        base = _ident(name)
        nm, k = base, 2
        while nm in taken:
            nm, k = f"{base}_{k}", k + 1
        taken.add(nm)
        out.append(FmuVariable(nm, vr, causality, group, idx, desc, unit, start))
    return out


def _dependencies(design: Design, sample_time: float, boundary_layer) -> list[list[int]]:
    """Per output (u, xbarhat, yc in order, then a latched gate's): the inputs it depends on structurally
    (0-based), from the CasADi step, in the running observer and at the first sample (z0 = xbar0 - H y0),
    united. A gate, piecewise constant in y, takes the dependencies of the fault estimates it compares."""
    fn = step_function(design, sample_time, boundary_layer=boundary_layer)
    nbar, p, lf = int(design.dims.nbar), int(design.dims.p), int(design.dims.lf)
    latches = lf if design.latched else 0
    z, y = ca.SX.sym("z", design.nz), ca.SX.sym("y", p)
    z0 = ca.vertcat(  # the gate's latches and memories start at 0, as init sets them
        ca.DM(design.xbar0) - ca.mtimes(ca.DM(np.asarray(design.H, float)), y), ca.DM.zeros(design.nz - nbar)
    )
    deps = None
    for zz in (z, z0):
        outs = fn(zz, y)
        fhat = outs[2][nbar - lf :]
        gates = [ca.sum1(fhat)] * latches  # each gate compares every estimate
        expr = ca.vertcat(outs[1], outs[2], outs[3], *gates)
        sp = np.array(ca.DM(ca.jacobian(expr, y).sparsity(), 1)) != 0
        deps = sp if deps is None else (deps | sp)
    return [list(np.flatnonzero(row)) for row in deps]


def _model_description(design, variables, sample_time, deps, guid, sources, mid) -> str:
    root = ET.Element(
        "fmiModelDescription",
        {
            "fmiVersion": "2.0",
            "modelName": xml_text(design.plant),
            "guid": guid,
            "description": f"observer / fault estimator / tolerant controller of plant {xml_text(design.plant)} "
            f"(design variant {design.variant}, {'certified' if design.certified else 'NOT CERTIFIED'}); "
            f"one fmi2DoStep = one sample, fixed step Ts = {sample_time!r}",
            "generationTool": f"{_TOOL} {_version()}",
            "variableNamingConvention": "flat",
            "numberOfEventIndicators": "0",
        },
    )
    cs = ET.SubElement(
        root,
        "CoSimulation",
        {
            "modelIdentifier": mid,
            "needsExecutionTool": "false",
            "canHandleVariableCommunicationStepSize": "false",
            "canInterpolateInputs": "false",
            "maxOutputDerivativeOrder": "0",
            "canRunAsynchronuously": "false",
            "canBeInstantiatedOnlyOncePerProcess": "false",
            "canNotUseMemoryManagementFunctions": "false",
            "canGetAndSetFMUstate": "false",
            "canSerializeFMUstate": "false",
            "providesDirectionalDerivative": "false",
        },
    )
    files = ET.SubElement(cs, "SourceFiles")
    for name in sources:
        ET.SubElement(files, "File", {"name": name})
    units = sorted({v.unit for v in variables if v.unit})
    if units:
        ud = ET.SubElement(root, "UnitDefinitions")
        for u in units:
            ET.SubElement(ud, "Unit", {"name": xml_text(u)})
    cats = ET.SubElement(root, "LogCategories")
    ET.SubElement(cats, "Category", {"name": "logStatusError", "description": "errors (always logged)"})
    ET.SubElement(root, "DefaultExperiment", {"startTime": "0", "stepSize": repr(float(sample_time))})
    mv = ET.SubElement(root, "ModelVariables")
    for v in variables:
        attrs = {
            "name": v.name,
            "valueReference": str(v.value_reference),
            "description": xml_text(v.description),
            "causality": v.causality,
            "variability": "discrete",
        }
        if v.causality == "output":
            attrs["initial"] = "calculated"
        sv = ET.SubElement(mv, "ScalarVariable", attrs)
        real = {}
        if v.unit:
            real["unit"] = xml_text(v.unit)
        if v.start is not None:
            real["start"] = repr(float(v.start))
        ET.SubElement(sv, "Real", real)
    ms = ET.SubElement(root, "ModelStructure")
    outs = [v for v in variables if v.causality == "output"]
    input_index = {v.index: v.value_reference + 1 for v in variables if v.causality == "input"}
    for tag in ("Outputs", "InitialUnknowns"):
        el = ET.SubElement(ms, tag)
        for v, dep in zip(outs, deps):
            ET.SubElement(
                el,
                "Unknown",
                {
                    "index": str(v.value_reference + 1),
                    "dependencies": " ".join(str(input_index[j]) for j in dep),
                },
            )
    ET.indent(root, space="  ")
    return '<?xml version="1.0" encoding="UTF-8"?>\n' + ET.tostring(root, encoding="unicode") + "\n"


def _platform() -> tuple[str, str]:
    """The FMI 2.0 binaries folder of this platform and its shared-library suffix."""
    bits = 64 if sys.maxsize > 2**32 else 32
    system = platform.system()
    if system == "Linux":
        return f"linux{bits}", ".so"
    if system == "Darwin":
        return f"darwin{bits}", ".dylib"
    raise CodegenError(
        f"--fmu builds the FMU's binary with the system C compiler on Linux or macOS; this is {system}. "
        "Generate without --fmu and build an FMU from the C sources with your platform's tools"
    )


def is_fte_fmu(path: str | os.PathLike) -> bool:
    """True when ``path`` is an FMU that fte wrote (its modelDescription.xml names fte_casadi as its tool)."""
    try:
        with zipfile.ZipFile(path) as z:
            root = ET.fromstring(z.read("modelDescription.xml"))
    except (OSError, KeyError, zipfile.BadZipFile, ET.ParseError):
        return False
    return root.tag == "fmiModelDescription" and root.get("generationTool", "").startswith(_TOOL + " ")


def check_fmu_target(design: Design, out_dir: str | os.PathLike) -> Path:
    """Refuse, before any work, what would make ``--fmu`` fail or destroy a user's file: no C compiler,
    an unsupported platform, or an existing ``<id>.fmu`` that fte did not write. Returns the FMU's path."""
    if build.find_compiler() is None:
        raise CodegenError(
            "--fmu needs a C compiler to build the FMU's binary for this platform, and none was found "
            "(looked for $CC, cc, gcc, clang on PATH); install one (e.g. `apt-get install gcc`) or set CC "
            "to it, or leave out --fmu to write the C sources only. Nothing was written"
        )
    _platform()
    target = fmu_path(design, out_dir)
    if target.is_dir():
        raise CodegenError(f"{target} is a directory; the FMU cannot be written there: choose another --out")
    if target.exists() and not is_fte_fmu(target):
        raise CodegenError(
            f"{target} exists and was not written by fte (it is not an FMU of `fte codegen --fmu`): it is "
            "left untouched; choose another --out, or move that file away first. Nothing was written"
        )
    return target


def _c_strings(names) -> str:
    return ",\n".join(f'  "{c_string(n)}"' for n in names)


def _c_reals(values) -> str:
    return ",\n".join(f"  {float(v)!r}" for v in values)


def _guid(parts) -> str:
    h = hashlib.sha256()
    for part in parts:
        h.update(part.encode())
        h.update(b"\0")
    return "{" + str(uuid.UUID(h.hexdigest()[:32])) + "}"


def _zip_bytes(members: dict[str, bytes]) -> bytes:
    """The zip archive of ``members`` (fixed timestamps and modes: the same design gives the same bytes)."""
    import io

    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for name, data in members.items():
            info = zipfile.ZipInfo(name, _ZIP_TIME)
            info.compress_type = zipfile.ZIP_DEFLATED
            info.external_attr = (0o755 if name.startswith("binaries/") else 0o644) << 16
            z.writestr(info, data)
    return buf.getvalue()


def _write_zip(target: Path, data: bytes) -> None:
    """Write the archive whole or not at all (:func:`fte_casadi._atomic.atomic_write`)."""
    from .._atomic import atomic_write

    try:
        atomic_write(target, lambda fh: fh.write(data))
    except OSError as exc:
        raise CodegenError(f"cannot write the FMU {str(target)!r}: {exc.strerror or exc}") from None


def generate_fmu(
    design: Design | str | os.PathLike,
    out_dir: str | os.PathLike,
    *,
    sample_time: float | None = None,
    real: str = "double",
    boundary_layer: float | None = None,
) -> Path:
    """Write ``out_dir/<plant>.fmu``: an FMI 2.0 co-simulation FMU of the design's discrete step.

    Parameters
    ----------
    design : Design or path
        The design record, or the path of a design document.
    out_dir : path
        Created if needed. Only ``<model identifier>.fmu`` is written (atomically); an existing file
        of that name is replaced only when fte wrote it (:func:`is_fte_fmu`).
    sample_time, real, boundary_layer
        As for :func:`~fte_casadi.codegen._generate.generate_c`; ``sample_time`` is the FMU's fixed
        communication step (default: the design's sample time). The former keyword ``ts`` was removed
        in 0.2.0: giving it is a ``TypeError``.

    Returns
    -------
    Path
        The FMU written.

    Raises
    ------
    CodegenError
        No C compiler, an unsupported platform, a file in the way that fte did not write, or a
        failed compilation.

    Examples
    --------
    >>> import tempfile
    >>> from fte_casadi.design._record import Design
    >>> d = Design.load("generated/three_tank/design.json")  # doctest: +SKIP
    >>> generate_fmu(d, tempfile.mkdtemp()).name  # doctest: +SKIP
    'three_tank.fmu'
    """
    if isinstance(design, (str, os.PathLike)):
        design = Design.load(design)
    if not isinstance(design, Design):
        raise CodegenError(
            f"generate_fmu needs a Design record (Design.load(path)); got {type(design).__name__}"
        )
    if real not in ("double", "float"):
        raise ParameterError(f"--real must be one of ['double', 'float']; got {real!r}")
    sample_time = _check_sample_time(design, sample_time)
    target = check_fmu_target(design, out_dir)
    texts = c_texts(design, sample_time=sample_time, real=real, boundary_layer=boundary_layer)
    data = fmu_member(design, texts, sample_time=sample_time, real=real, boundary_layer=boundary_layer)
    prepare_dir(Path(out_dir))
    _write_zip(target, data)
    return target


def generate_c_and_fmu(design: Design, out_dir: str | os.PathLike, *, sample_time: float | None = None,
                       real: str = "double", boundary_layer: float | None = None) -> list[Path]:  # fmt: skip
    """The C of :func:`~fte_casadi.codegen._generate.generate_c` and its FMU (``<plant>.fmu``), put into
    ``out_dir`` as one set (``fte codegen --fmu``): a kill leaves the old C and FMU or the new ones."""
    if real not in ("double", "float"):
        raise ParameterError(f"--real must be one of ['double', 'float']; got {real!r}")
    sample_time = _check_sample_time(design, sample_time)
    if boundary_layer is None:  # the design's own (fte tune), as the simulation runs it
        boundary_layer = design.params.boundary_layer
    out = Path(out_dir)
    check_out(out)
    target = check_fmu_target(design, out)
    texts = c_texts(design, sample_time=sample_time, real=real, boundary_layer=boundary_layer)
    files = {name: text.encode("utf-8") for name, text in texts.items()}
    files[target.name] = fmu_member(
        design, texts, sample_time=sample_time, real=real, boundary_layer=boundary_layer
    )
    return write_c_set(out, files)


def fmu_member(
    design: Design, texts: dict[str, str], *, sample_time: float, real: str, boundary_layer
) -> bytes:
    """The FMU (the bytes of its zip archive) of the generated C ``texts`` (:func:`~._generate.c_texts` of the
    same ``design``, ``sample_time``, ``real`` and ``boundary_layer``), its binary compiled here."""
    folder, suffix = _platform()
    mid = model_identifier(design.plant)
    name = c_name(design.plant)
    variables = fmu_variables(design)
    deps = _dependencies(design, sample_time, boundary_layer)
    with tempfile.TemporaryDirectory(prefix="fte_fmu_") as tmp:
        src = Path(tmp, "sources")
        src.mkdir()
        for f, text in texts.items():
            (src / f).write_text(text)
        generated = {f: texts[f] for f in output_files(design.plant)}
        readme = generated.pop("README.md")
        wrapper_name = f"{mid}_fmi2.c"
        c_files = sorted([f for f in generated if f.endswith(".c")] + [wrapper_name])
        md_draft = _model_description(design, variables, sample_time, deps, "{GUID}", c_files, mid)
        guid = _guid([md_draft, *generated.values()])
        p = int(design.dims.p)
        wrapper = template.fill(
            template.TEMPLATES["fmu_wrapper"],
            dict(
                mid=mid,
                name=name,
                NAME=name.upper(),
                plant=c_comment(design.plant),
                version=_version(),
                guid=guid,
                ny=p,
                ny_last=p - 1,
                nvar_last=len(variables) - 1,
                sample_time_text=repr(sample_time),
                ngate=int(design.dims.lf) if design.latched else 0,
                gate_names=", gate" if design.latched else "",
                gate_out="  for (i = 0; i < NGATE; ++i) out[NU + NXBAR + NY + i] = (fmi2Real)st->z[NXBAR + i];\n"
                if design.latched
                else "",
                y_start=_c_reals(v.start for v in variables[:p]),
                var_names=_c_strings(v.name for v in variables),
            ),
        )
        (src / wrapper_name).write_text(wrapper)
        (src / FMI2_HEADER_NAME).write_text(template.read(template.TEMPLATES["fmi2_header"]))
        (src / "README.md").unlink()
        lib = Path(tmp, mid + suffix)
        build.compile_shared(src, lib, extra_flags=("-fvisibility=hidden",))
        members = {"modelDescription.xml": md_draft.replace("{GUID}", guid).encode()}
        members[f"binaries/{folder}/{mid}{suffix}"] = lib.read_bytes()
        for f in sorted(generated) + [wrapper_name, FMI2_HEADER_NAME]:
            members[f"sources/{f}"] = (src / f).read_bytes()
        members["documentation/README.md"] = readme.encode()
    return _zip_bytes(members)
