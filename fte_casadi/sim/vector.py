"""The vectorised Monte Carlo engine: a CasADi SX Function emitted as C over lanes of paths.

The closed-loop sample ``F: (state, w, sh) -> (next, rec, incr)`` (plant Euler-Maruyama step,
observer/controller step for the three runs, and the metric summands) stays the source of truth:
its algorithm (``instruction_id/input/output/constant``, CasADi's own register allocation of the
work vector) is written out instruction by instruction, each as an operation over ``V`` paths
held side by side (``w[slot][V]``), so that the C compiler vectorises across paths. Around it, a
loop over samples draws the random numbers per path (:mod:`.rng`), reads the inputs shared by all
paths at that sample (fault coefficients, masks), keeps the state in the lanes for the whole
horizon, accumulates the metric sums per path in time order, records a sample when asked, and
notes the first sample at which a path diverges. One call runs a range of paths; the caller splits
paths over threads (ctypes releases the GIL) or over Dask workers.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from . import rng
from .compile import cache_dir

__all__ = ["emit", "VectorEngine", "UnsupportedOperation", "LANES", "FLAGS"]

#: paths per lane group (8 doubles: one AVX-512 register, two AVX2 ones)
LANES = 8
#: compiler flags: IEEE semantics kept (no -ffast-math); -fno-trapping-math lets comparisons vectorise
FLAGS = ("-O3", "-fno-trapping-math", "-fno-math-errno", "-march=native", "-shared", "-fPIC")


class UnsupportedOperation(ValueError):
    """The Function uses a CasADi operation the emitter does not know."""


def _ops() -> dict[int, str]:
    """C expression templates of CasADi's SX operations (``{a}``, ``{b}`` the operands)."""
    t = {
        "OP_ASSIGN": "{a}", "OP_ADD": "{a} + {b}", "OP_SUB": "{a} - {b}", "OP_MUL": "{a} * {b}",
        "OP_DIV": "{a} / {b}", "OP_NEG": "-{a}", "OP_SQ": "{a} * {a}", "OP_TWICE": "2.0 * {a}",
        "OP_INV": "1.0 / {a}", "OP_EXP": "exp({a})", "OP_LOG": "log({a})", "OP_POW": "pow({a}, {b})",
        "OP_CONSTPOW": "pow({a}, {b})", "OP_SQRT": "sqrt({a})", "OP_SIN": "sin({a})", "OP_COS": "cos({a})",
        "OP_TAN": "tan({a})", "OP_ASIN": "asin({a})", "OP_ACOS": "acos({a})", "OP_ATAN": "atan({a})",
        "OP_LT": "(double)({a} < {b})", "OP_LE": "(double)({a} <= {b})", "OP_EQ": "(double)({a} == {b})",
        "OP_NE": "(double)({a} != {b})", "OP_NOT": "(double)(!{a})", "OP_AND": "(double)({a} && {b})",
        "OP_OR": "(double)({a} || {b})", "OP_FLOOR": "floor({a})", "OP_CEIL": "ceil({a})",
        "OP_FMOD": "fmod({a}, {b})", "OP_FABS": "fabs({a})", "OP_SIGN": "({a} < 0 ? -1.0 : {a} > 0 ? 1.0 : {a})",
        "OP_COPYSIGN": "copysign({a}, {b})", "OP_IF_ELSE_ZERO": "({a} ? {b} : 0.0)", "OP_ERF": "erf({a})",
        "OP_FMIN": "fmin({a}, {b})", "OP_FMAX": "fmax({a}, {b})", "OP_SINH": "sinh({a})", "OP_COSH": "cosh({a})",
        "OP_TANH": "tanh({a})", "OP_ASINH": "asinh({a})", "OP_ACOSH": "acosh({a})", "OP_ATANH": "atanh({a})",
        "OP_ATAN2": "atan2({a}, {b})", "OP_LOG1P": "log1p({a})", "OP_EXPM1": "expm1({a})",
        "OP_HYPOT": "hypot({a}, {b})",
    }  # fmt: skip
    return {getattr(ca, k): v for k, v in t.items() if hasattr(ca, k)}


#: operations the compiler cannot vectorise without -ffast-math (calls into libm): each gets its own lane loop
_CALLS = ("exp(", "log(", "pow(", "sin(", "cos(", "tan(", "asin(", "acos(", "atan(", "fmod(", "erf(", "fmin(",
          "fmax(", "sinh(", "cosh(", "tanh(", "asinh(", "acosh(", "atanh(", "atan2(", "log1p(", "expm1(", "hypot(",
          "floor(", "ceil(", "copysign(")  # fmt: skip


def _instructions(F: ca.Function) -> list[tuple]:
    """``(kind, out_slot, in_slots, text)`` per instruction; ``text`` uses ``{0}``, ``{1}`` for inputs."""
    ops = _ops()
    names = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}
    out = []
    for k in range(F.n_instructions()):
        op = F.instruction_id(k)
        ins, outs = list(F.instruction_input(k)), list(F.instruction_output(k))
        if op == ca.OP_INPUT:
            i, nz = ins
            src = (
                f"st[{nz}][l]"
                if i == 0
                else (("dw[l]" if nz == 0 else f"dd[{nz - 1}][l]") if i == 1 else f"sh[{nz}]")
            )
            out.append(("expr", outs[0], [], src))
        elif op == ca.OP_CONST:
            out.append(("expr", outs[0], [], repr(float(F.instruction_constant(k)))))
        elif op == ca.OP_OUTPUT:
            i, nz = outs
            dest = {0: f"nx[{nz}][l] = ", 1: f"if (recnow) rb[{nz}][l] = ", 2: f"acc[{nz}][l] += "}[min(i, 2)]
            out.append(("store", None, [ins[0]], dest + "{0};"))
        elif op in ops:
            tmpl = ops[op].replace("{a}", "{0}").replace("{b}", "{1}")
            kind = "call" if any(c in tmpl for c in _CALLS) else "expr"
            out.append((kind, outs[0], ins[:2] if "{1}" in tmpl else ins[:1], tmpl))
        else:
            raise UnsupportedOperation(
                f"the vectorised engine cannot emit CasADi operation {names.get(op, op)}"
            )
    return out


def _body(F: ca.Function) -> list[str]:
    """The sample as C: runs of vectorisable instructions fused into one lane loop each (work slots as
    local scalars, so values stay in registers); a libm call gets a lane loop of its own; between them
    only the slots still needed travel through the lane arrays ``w[slot][l]``."""
    ins = _instructions(F)
    # segments: maximal runs of non-call instructions
    segs, cur = [], []
    for t in ins:
        if t[0] == "call":
            if cur:
                segs.append(cur)
                cur = []
            segs.append([t])
        else:
            cur.append(t)
    if cur:
        segs.append(cur)
    # liveness across segments: a slot written in a segment is stored if a later segment reads it first
    reads_later: set[int] = set()
    live_out: list[set[int]] = [set() for _ in segs]
    for g in range(len(segs) - 1, -1, -1):
        written_here = {t[1] for t in segs[g] if t[1] is not None}
        live_out[g] = written_here & reads_later
        # slots read in this segment before being written in it
        first_read, seen = set(), set()
        for t in segs[g]:
            first_read |= {s for s in t[2] if s not in seen}
            if t[1] is not None:
                seen.add(t[1])
        reads_later = (reads_later - written_here) | first_read
    lines = []
    defined: set[int] = set()
    for g, seg in enumerate(segs):
        if seg[0][0] == "call":
            _, o, a, tmpl = seg[0]
            lines.append(f"  for (l = 0; l < V; ++l) w[{o}][l] = {tmpl.format(*[f'w[{x}][l]' for x in a])};")
            defined.add(o)
            continue
        local, loads, seen = set(), [], set()
        for _, o, a, _ in seg:
            for x in a:
                if x not in seen and x not in local:
                    loads.append(x)
                    local.add(x)
            if o is not None:
                local.add(o)
                seen.add(o)
        stmts = [f"double {', '.join(f's{x}' for x in sorted(local))};"] if local else []
        stmts += [f"s{x} = w[{x}][l];" for x in loads]
        for _, o, a, tmpl in seg:
            e = tmpl.format(*[f"s{x}" for x in a])
            stmts.append(e if o is None else f"s{o} = {e};")
        stmts += [f"w[{x}][l] = s{x};" for x in sorted(live_out[g])]
        lines.append("  for (l = 0; l < V; ++l) {\n    " + "\n    ".join(stmts) + "\n  }")
    return lines


def emit(F: ca.Function, x_slots: list[int], name: str = "fte_mc") -> str:
    """C source of the lane engine of ``F: (state, w, sh) -> (next, rec, incr)``.

    ``x_slots``: the entries of ``state`` that are plant states (checked for divergence).
    Raises :class:`UnsupportedOperation` on an operation outside :func:`_ops`."""
    if not F.is_a("SXFunction"):
        F = F.expand()
    ns, nw, nsh = F.size1_in(0), F.size1_in(1), F.size1_in(2)
    nrec, ninc = F.size1_out(1), F.size1_out(2)
    ld = nw - 1
    body = _body(F)
    xs = ", ".join(str(j) for j in x_slots) or "0"
    nslot = 2 + ld
    return f"""/* generated by fte_casadi.sim.vector from a CasADi Function: do not edit */
#include <math.h>
#include <stdint.h>
#define V {LANES}
#define NS {ns}
#define NREC {nrec}
#define NINC {ninc}
#define NSH {nsh}
#define LD {max(ld, 1)}
{rng.C_SOURCE}
static const int XS[] = {{{xs}}};
#define SZW {max(F.sz_w(), 1)}
static void fte_sample(double w[SZW][V], double st[NS][V], double nx[NS][V], double acc[NINC][V],
                       double rb[NREC][V], const double *sh, const double *dw, double dd[LD][V], int recnow) {{
  int l;
{chr(10).join(body)}
}}

/* paths [path0, path0 + npaths): state S0 (npaths x NS) -> S1; sums ACC (npaths x NINC) over samples
   0 .. nsamp - 1; REC (npaths x nrs x NREC) every `every` samples when REC is not NULL; DIV: first
   diverging sample or -1. SH: (nsamp x NSH) shared inputs. Random numbers: rng.py. */
void {name}(long npaths, long path0, uint64_t seed, long nsamp, const double *SH, double sqdt, double damp,
            const double *S0, double *S1, double *ACC, long every, double *REC, long *DIV, double bound) {{
  double w[SZW][V], st[NS][V], nx[NS][V], acc[NINC][V], rb[NREC][V], dw[V], dd[LD][V];
  uint64_t key[V];
  long div[V];
  long nrs = every > 0 ? (nsamp - 1) / every + 1 : 0;
  long c0, k;
  int l, j;
  for (c0 = 0; c0 < npaths; c0 += V) {{
    int nl = (npaths - c0) < V ? (int)(npaths - c0) : V;
    for (l = 0; l < V; ++l) {{
      long p = c0 + (l < nl ? l : 0);
      for (j = 0; j < NS; ++j) st[j][l] = S0[p * NS + j];
      for (j = 0; j < NINC; ++j) acc[j][l] = 0.0;
      key[l] = fte_key(seed, (uint64_t)(path0 + p));
      div[l] = -1;
    }}
    for (k = 0; k < nsamp; ++k) {{
      const double *sh = SH + k * NSH;
      int recnow = REC != 0 && k % every == 0;
      uint64_t cb = (uint64_t)k * {nslot};
      for (l = 0; l < V; ++l) {{
        double u1 = 1.0 - fte_u01(key[l], cb + 1), u2 = fte_u01(key[l], cb + 2);
        dw[l] = sqdt * sqrt(-2.0 * log(u1)) * cos(6.283185307179586 * u2);
        for (j = 0; j < {ld}; ++j) dd[j][l] = damp * (2.0 * fte_u01(key[l], cb + 3 + j) - 1.0);
      }}
      fte_sample(w, st, nx, acc, rb, sh, dw, dd, recnow);
      if (recnow) {{
        for (l = 0; l < nl; ++l)
          for (j = 0; j < NREC; ++j) REC[((c0 + l) * nrs + k / every) * NREC + j] = rb[j][l];
      }}
      for (j = 0; j < (int)(sizeof(XS) / sizeof(XS[0])); ++j)
        for (l = 0; l < V; ++l)
          if (div[l] < 0 && !(fabs(st[XS[j]][l]) <= bound)) div[l] = k;
      for (j = 0; j < NS; ++j)
        for (l = 0; l < V; ++l) st[j][l] = nx[j][l];
    }}
    for (l = 0; l < nl; ++l) {{
      for (j = 0; j < NS; ++j) S1[(c0 + l) * NS + j] = st[j][l];
      for (j = 0; j < NINC; ++j) ACC[(c0 + l) * NINC + j] = acc[j][l];
      DIV[c0 + l] = div[l];
    }}
  }}
}}
"""


def _cpu_tag() -> str:
    """What -march=native depends on: the machine and its CPU flags."""
    try:
        flags = next(
            (ln for ln in Path("/proc/cpuinfo").read_text().splitlines() if ln.startswith("flags")), ""
        )
    except OSError:
        flags = ""
    return platform.machine() + platform.processor() + flags


def _compiler() -> str | None:
    for cc in (os.environ.get("CC"), "cc", "gcc", "clang"):
        if cc and shutil.which(cc):
            return cc
    return None


class VectorEngine:
    """The compiled lane engine of one closed-loop sample Function (compiled once, cached on disk)."""

    def __init__(self, F: ca.Function, x_slots: list[int], name: str = "fte_mc"):
        src = emit(F, x_slots, name)
        cc = _compiler()
        if cc is None:
            raise UnsupportedOperation("no C compiler found (cc, gcc, clang or $CC)")
        key = hashlib.sha256((src + cc + " ".join(FLAGS) + _cpu_tag()).encode()).hexdigest()[:20]
        folder = cache_dir()
        lib = folder / f"{name}_{key}.so"
        if not lib.exists():
            folder.mkdir(parents=True, exist_ok=True)
            with tempfile.TemporaryDirectory() as tmp:
                c = Path(tmp) / f"{name}.c"
                c.write_text(src)
                out = Path(tmp) / "lib.so"
                proc = subprocess.run(
                    [cc, *FLAGS, "-o", str(out), str(c), "-lm"], capture_output=True, text=True
                )
                if proc.returncode != 0:
                    raise UnsupportedOperation(
                        f"compiling the vectorised engine failed: {proc.stderr[-1500:]}"
                    )
                fd, tmp_lib = tempfile.mkstemp(dir=folder, suffix=".so.tmp")
                os.close(fd)
                shutil.copyfile(out, tmp_lib)
                os.replace(tmp_lib, lib)  # atomic: parallel workers may compile the same engine
        self.lib = ctypes.CDLL(str(lib))
        self.fn = getattr(self.lib, name)
        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_long)
        self.fn.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_uint64, ctypes.c_long, dp, ctypes.c_double,
                            ctypes.c_double, dp, dp, dp, ctypes.c_long, dp, lp, ctypes.c_double]  # fmt: skip
        self.fn.restype = None
        self.ns, self.nrec, self.ninc, self.nsh = F.size1_in(0), F.size1_out(1), F.size1_out(2), F.size1_in(2)
        self.source = src

    def run(self, path0: int, S0: np.ndarray, seed: int, SH: np.ndarray, sqdt: float, damp: float,
            bound: float, every: int = 0) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:  # fmt: skip
        """Run paths ``path0 ..`` from states ``S0`` (paths, ns) over the samples of ``SH``.

        Returns ``(S1, ACC, DIV, REC)``; ``REC`` (paths, samples, nrec) only when ``every > 0``."""
        P, nsamp = S0.shape[0], SH.shape[0]
        S0 = np.ascontiguousarray(S0, dtype=np.float64)
        SH = np.ascontiguousarray(SH, dtype=np.float64)
        S1 = np.empty_like(S0)
        ACC = np.empty((P, self.ninc))
        DIV = np.empty(P, dtype=np.int_)
        REC = np.empty((P, (nsamp - 1) // every + 1, self.nrec)) if every > 0 else None
        dp = ctypes.POINTER(ctypes.c_double)
        self.fn(P, int(path0), ctypes.c_uint64(int(seed) & 0xFFFFFFFFFFFFFFFF), nsamp, SH.ctypes.data_as(dp),
                float(sqdt), float(damp), S0.ctypes.data_as(dp), S1.ctypes.data_as(dp), ACC.ctypes.data_as(dp),
                int(every), REC.ctypes.data_as(dp) if REC is not None else None,
                DIV.ctypes.data_as(ctypes.POINTER(ctypes.c_long)), float(bound))  # fmt: skip
        return S1, ACC, DIV, REC
