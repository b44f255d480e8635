"""The vectorised Monte Carlo engine: a CasADi SX Function emitted as C over lanes of paths.

The closed-loop sample ``F: (state, w, sh) -> (next, rec, incr)`` (plant Euler-Maruyama step,
observer/controller step for the three runs, and the metric summands) stays the source of truth:
its algorithm (``instruction_id/input/output/constant``, CasADi's own register allocation of the
work vector) is written out instruction by instruction, each as one operation on a vector of
``V`` paths side by side (GCC/Clang vector extensions: ``fte_vd w12 = w3 * w7;``), so the code is
vectorised across paths by construction, not by the compiler's auto-vectoriser; calls into the C
library (``sin``, ``exp``, ``pow``, ...) run lane by lane. Around it, a loop over samples draws
the random numbers per path (:mod:`._rng`), reads the inputs shared by all paths at that sample
(fault coefficients, masks), keeps the state in the lanes for the whole horizon, accumulates the
metric sums per path in time order, records a sample when asked, and notes the first sample at
which a path diverges. One call runs a range of paths; the caller splits paths over threads
(ctypes releases the GIL) or over Dask workers.

IEEE semantics are kept: no ``-ffast-math``, no fused multiply-adds (``-ffp-contract=off``), and
``fmin``/``fmax``/``sign``/``if_else`` written as comparisons and selections that give the C
library's results (NaN ignored by fmin/fmax, sign(NaN) = NaN). The engine therefore computes every
operation exactly as CasADi's own generated C does: its trajectories equal the per-path engine's
bit for bit on the same random numbers.

The fast mode (``exact=False``; docs/simulation.md) compiles the same engine with contraction into
fused multiply-adds (:data:`FAST_FLAGS`), calls glibc's vector math library (libmvec) once per lane
vector for ``sin``, ``log``, ... (:data:`_VMATH`) and draws the same uniforms on integer lane vectors;
it stays free of horizontal operations across lanes, so every path runs the same instructions
whatever lane and chunk it lands in, and the numbers do not depend on how the paths are split.

A Function with an operation the emitter does not know (a lookup table's ``OP_CALL``, say) runs
through CasADi's own generated C instead, called lane by lane inside the same loop (the same
numbers, several times slower; :attr:`VectorEngine.note` says so).
"""

from __future__ import annotations

import ctypes
import hashlib
import math
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from .._toolchain import cache_dir, find_compiler
from ..errors import UnsupportedOperation
from . import _rng as rng

__all__ = []  # public: docs/api.md

#: paths per lane vector (8 doubles: one AVX-512 register, two AVX2 ones)
LANES = 8
#: at most this many paths per call of the compiled engine (the unit of progress, threads and cluster tasks)
CHUNK = 256


def auto_chunk(paths: int, threads: int) -> int:
    """Paths per chunk: about four chunks per thread (load balance), whole lane vectors, at most CHUNK."""
    per = math.ceil(paths / (4 * max(int(threads), 1)))
    return max(LANES, min(CHUNK, LANES * math.ceil(per / LANES)))


#: compiler flags: IEEE semantics kept (no -ffast-math); -ffp-contract=off: no fused multiply-adds, so
#: every operation rounds as in CasADi's own C and the numbers do not depend on whether a CPU has FMA.
#: -O1, not -O3: gcc 12 compiled the manipulator's engine (61 kB of C) in 4.0 s against 11.2 s at -O3 (-O2 7.7 s),
#: and the engine then ran as fast (128 paths of its scenario: 0.61 s against 0.60 s; the quadruple tank's 64
#: paths 0.75 s against 0.83 s; the best of three, 2-core Zen 3) with the same numbers to the bit (no reassociation
#: at any level): a new design's first run waits for the compiler, and it waits less
FLAGS = ("-O1", "-fno-trapping-math", "-fno-math-errno", "-ffp-contract=off", "-march=native", "-shared", "-fPIC")  # fmt: skip
#: the fast mode's flags (``exact=False``): the same, with contraction into fused multiply-adds allowed;
#: still no -ffast-math (no reassociation, NaN and infinities kept: the divergence check relies on them)
FAST_FLAGS = tuple("-ffp-contract=fast" if f == "-ffp-contract=off" else f for f in FLAGS)


#: vector expressions of CasADi's SX operations; ``{a}``, ``{b}`` the operands (``fte_vd`` values)
_VEC = {
    "OP_ASSIGN": "{a}", "OP_LIFT": "{a}", "OP_ADD": "{a} + {b}", "OP_SUB": "{a} - {b}", "OP_MUL": "{a} * {b}",
    "OP_DIV": "{a} / {b}", "OP_NEG": "-{a}", "OP_SQ": "{a} * {a}", "OP_TWICE": "FTE_BC(2.0) * {a}",
    "OP_INV": "FTE_BC(1.0) / {a}",
    "OP_LT": "FTE_TRUE({a} < {b})", "OP_LE": "FTE_TRUE({a} <= {b})", "OP_EQ": "FTE_TRUE({a} == {b})",
    "OP_NE": "FTE_TRUE({a} != {b})", "OP_NOT": "FTE_TRUE({a} == FTE_BC(0.0))",
    "OP_AND": "FTE_TRUE(({a} != FTE_BC(0.0)) & ({b} != FTE_BC(0.0)))",
    "OP_OR": "FTE_TRUE(({a} != FTE_BC(0.0)) | ({b} != FTE_BC(0.0)))",
    # if_else_zero(c, y) = c == 0 ? 0 : y (a NaN condition is true, as in C)
    "OP_IF_ELSE_ZERO": "(fte_vd)((fte_vl){b} & ({a} != FTE_BC(0.0)))",
    "OP_FABS": "(fte_vd)((fte_vl){a} & ~(fte_vl)FTE_BC(-0.0))",
    "OP_COPYSIGN": "(fte_vd)(((fte_vl){a} & ~(fte_vl)FTE_BC(-0.0)) | ((fte_vl){b} & (fte_vl)FTE_BC(-0.0)))",
    "OP_SIGN": "FTE_SEL({a} < FTE_BC(0.0), FTE_BC(-1.0), FTE_SEL({a} > FTE_BC(0.0), FTE_BC(1.0), {a}))",
    # the C library's fmin/fmax: the other operand when one is NaN; the second one on a tie (+0/-0)
    "OP_FMIN": "FTE_SEL(({a} < {b}) | ({b} != {b}), {a}, {b})",
    "OP_FMAX": "FTE_SEL(({a} > {b}) | ({b} != {b}), {a}, {b})",
}  # fmt: skip
#: operations that call the C library, lane by lane
_CALL = {
    "OP_EXP": "exp", "OP_LOG": "log", "OP_SQRT": "sqrt", "OP_SIN": "sin", "OP_COS": "cos", "OP_TAN": "tan",
    "OP_ASIN": "asin", "OP_ACOS": "acos", "OP_ATAN": "atan", "OP_FLOOR": "floor", "OP_CEIL": "ceil", "OP_ERF": "erf",
    "OP_SINH": "sinh", "OP_COSH": "cosh", "OP_TANH": "tanh", "OP_ASINH": "asinh", "OP_ACOSH": "acosh",
    "OP_ATANH": "atanh", "OP_LOG1P": "log1p", "OP_EXPM1": "expm1",
    "OP_POW": "pow", "OP_CONSTPOW": "pow", "OP_FMOD": "fmod", "OP_REMAINDER": "remainder", "OP_ATAN2": "atan2",
    "OP_HYPOT": "hypot",
}  # fmt: skip
_BINARY = {"OP_POW", "OP_CONSTPOW", "OP_FMOD", "OP_REMAINDER", "OP_ATAN2", "OP_HYPOT"}
#: the fast mode's calls into glibc's vector math library (libmvec, x86-64): one call per lane vector
#: (``_ZGVeN8v_sin`` with AVX-512, two ``_ZGVdN4v_sin`` with AVX2); the rest stay lane by lane (``sqrt``,
#: ``floor``, ``ceil`` become vector instructions anyway)
_VMATH = {
    "OP_EXP": "exp", "OP_LOG": "log", "OP_SIN": "sin", "OP_COS": "cos", "OP_TAN": "tan", "OP_ASIN": "asin",
    "OP_ACOS": "acos", "OP_ATAN": "atan", "OP_ERF": "erf", "OP_SINH": "sinh", "OP_COSH": "cosh", "OP_TANH": "tanh",
    "OP_ASINH": "asinh", "OP_ACOSH": "acosh", "OP_ATANH": "atanh", "OP_LOG1P": "log1p", "OP_EXPM1": "expm1",
    "OP_POW": "pow", "OP_CONSTPOW": "pow", "OP_ATAN2": "atan2", "OP_HYPOT": "hypot",
}  # fmt: skip


def _op_names() -> dict[int, str]:
    return {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}


def unsupported(F: ca.Function) -> list[str]:
    """The operations of ``F`` (SX) that the emitter cannot write as lane vectors (empty: none)."""
    names = _op_names()
    known = set(_VEC) | set(_CALL) | {"OP_INPUT", "OP_OUTPUT", "OP_CONST"}
    ops = {names.get(F.instruction_id(k), str(F.instruction_id(k))) for k in range(F.n_instructions())}
    return sorted(ops - known)


def _prelude(lanes: int = LANES) -> str:
    bc = ", ".join(["(c)"] * lanes)
    return f"""typedef double fte_vd __attribute__((vector_size({8 * lanes})));
typedef double fte_vdu __attribute__((vector_size({8 * lanes}), aligned(8)));
typedef long long fte_vl __attribute__((vector_size({8 * lanes})));
#define FTE_BC(c) ((fte_vd){{{bc}}})
#define FTE_TRUE(m) ((fte_vd)((fte_vl)FTE_BC(1.0) & (m)))
#define FTE_SEL(m, a, b) ((fte_vd)(((fte_vl)(a) & (m)) | ((fte_vl)(b) & ~(m))))
#define FTE_LD(p) (*(const fte_vdu *)(p))
#define FTE_ST(p, v) (*(fte_vdu *)(p) = (v))"""


def _vmath_prelude(fns: set[str], vmath: bool) -> str:
    """``fte_v_NAME(fte_vd[, fte_vd])`` for the functions ``fns``: libmvec's variant for 8 lanes (AVX-512)
    or two of its 4-lane variant (AVX2) when ``vmath``, else (or on other CPUs) the C library lane by lane.
    Every lane's result depends on that lane's operands only, whatever the other lanes hold."""
    out = ["#define FTE_ABS(a) ((fte_vd)((fte_vl)(a) & ~(fte_vl)FTE_BC(-0.0)))"]
    if vmath:
        out.append("#if defined(__x86_64__) && defined(__AVX512F__)\n#define FTE_VM 8\n#include <immintrin.h>\n"
                   "#elif defined(__x86_64__) && defined(__AVX2__)\n#define FTE_VM 4\n#include <immintrin.h>\n"
                   "#else\n#define FTE_VM 0\n#endif")  # fmt: skip
    for f in sorted(fns):
        binary = f in {"pow", "atan2", "hypot"}
        v = "vv" if binary else "v"
        par = "fte_vd a, fte_vd b" if binary else "fte_vd a"
        lane = "a[l], b[l]" if binary else "a[l]"
        scalar = f"  fte_vd r; int l;\n  for (l = 0; l < V; ++l) r[l] = {f}({lane});\n  return r;\n"
        if not vmath:
            out.append(f"static inline fte_vd fte_v_{f}({par}) {{\n{scalar}}}")
            continue
        for w, isa, t in ((8, "e", "__m512d"), (4, "d", "__m256d")):
            args = "ua.h[i], ub.h[i]" if binary else "ua.h[i]"
            ub = " ub = {b}," if binary else ""
            out.append(f"""#{"if" if w == 8 else "elif"} FTE_VM == {w}
{t} _ZGV{isa}N{w}{v}_{f}({", ".join([t] * (2 if binary else 1))});
static inline fte_vd fte_v_{f}({par}) {{
  union {{ fte_vd v; {t} h[V / {w}]; }} ua = {{a}},{ub} r;
  int i;
  for (i = 0; i < V / {w}; ++i) r.h[i] = _ZGV{isa}N{w}{v}_{f}({args});
  return r.v;
}}""")
        out.append(f"#else\nstatic inline fte_vd fte_v_{f}({par}) {{\n{scalar}}}\n#endif")
    return "\n".join(out)


def _fast_rng(lanes: int) -> str:
    """_rng.py's ``fte_mix``, ``fte_u01`` and ``fte_p01`` on integer lane vectors (the same integers, so
    the same uniforms: the conversions to double are exact)."""
    bcu = ", ".join(["(c)"] * lanes)
    return f"""typedef unsigned long long fte_vu __attribute__((vector_size({8 * lanes})));
#define FTE_BCU(c) ((fte_vu){{{bcu}}})
static inline fte_vu fte_mixv(fte_vu z) {{
  z = (z ^ (z >> 30)) * FTE_BCU(UINT64_C({rng._M1:#x}));
  z = (z ^ (z >> 27)) * FTE_BCU(UINT64_C({rng._M2:#x}));
  return z ^ (z >> 31);
}}
static inline fte_vd fte_u01v(fte_vu key, uint64_t c) {{
  fte_vu z = fte_mixv(key + FTE_BCU(c * UINT64_C({rng.GOLDEN:#x})));
  return __builtin_convertvector((fte_vl)(z >> 11), fte_vd) * FTE_BC(0x1.0p-53);
}}
static inline fte_vd fte_p01v(fte_vu key, uint64_t c) {{
  fte_vu z = fte_mixv(key + FTE_BCU(c * UINT64_C({rng.GOLDEN:#x})));
  return (__builtin_convertvector((fte_vl)(z >> 12), fte_vd) + FTE_BC(0.5)) * FTE_BC(0x1.0p-52);
}}"""


def _c_double(v: float) -> str:
    """A C literal of ``v`` that reads back exactly (infinities and NaN from math.h)."""
    if math.isnan(v):
        return "NAN"
    if math.isinf(v):
        return "INFINITY" if v > 0 else "-INFINITY"
    return repr(v)


def _body(F: ca.Function, exact: bool = True, ld: int | None = None) -> list[str]:
    """The sample as C statements on lane vectors, one per instruction of ``F``; work slots are
    CasADi's (``F.sz_w()`` vector variables, reused as CasADi reuses them). Not ``exact``: the
    functions of :data:`_VMATH` one call per lane vector (``fte_v_sin(w3)``)."""
    names = _op_names()
    ld = F.size1_in(1) - 1 if ld is None else ld
    lines = [f"  fte_vd {', '.join(f'w{i}' for i in range(max(F.sz_w(), 1)))};", "  int l;"]
    for k in range(F.n_instructions()):
        op = F.instruction_id(k)
        nm = names.get(op, str(op))
        ins, outs = list(F.instruction_input(k)), list(F.instruction_output(k))
        if op == ca.OP_INPUT:
            i, nz = ins
            if i == 0:
                src = f"FTE_LD(st[{nz}])"
            elif i == 1:
                src = (
                    "FTE_LD(dw)"
                    if nz == 0
                    else (f"FTE_LD(dd[{nz - 1}])" if nz <= ld else f"FTE_LD(dv[{nz - 1 - ld}])")
                )
            elif i == 2:
                src = f"FTE_BC(sh[{nz}])"
            else:
                src = f"par[{nz}]"
            lines.append(f"  w{outs[0]} = {src};")
        elif op == ca.OP_CONST:
            lines.append(f"  w{outs[0]} = FTE_BC({_c_double(float(F.instruction_constant(k)))});")
        elif op == ca.OP_OUTPUT:
            i, nz = outs
            a = f"w{ins[0]}"
            lines.append({0: f"  FTE_ST(nx[{nz}], {a});", 1: f"  if (recnow) FTE_ST(rb[{nz}], {a});",
                          2: f"  FTE_ST(acc[{nz}], FTE_LD(acc[{nz}]) + {a});",
                          3: f"  FTE_ST(pm[{nz}], {a});"}[min(i, 3)])  # fmt: skip
        elif nm in _VEC:
            b = f"w{ins[1]}" if len(ins) > 1 else ""
            lines.append(f"  w{outs[0]} = {_VEC[nm].format(a=f'w{ins[0]}', b=b)};")
        elif nm in _VMATH and not exact:
            b = f", w{ins[1]}" if nm in _BINARY else ""
            lines.append(f"  w{outs[0]} = fte_v_{_VMATH[nm]}(w{ins[0]}{b});")
        elif nm in _CALL:
            args = f"w{ins[0]}[l], w{ins[1]}[l]" if nm in _BINARY else f"w{ins[0]}[l]"
            lines.append(f"  for (l = 0; l < V; ++l) w{outs[0]}[l] = {_CALL[nm]}({args});")
        else:
            raise UnsupportedOperation(f"the vectorised engine cannot emit CasADi operation {nm}")
    return lines


def _casadi_body(F: ca.Function, ld: int) -> tuple[str, list[str]]:
    """CasADi's own C of ``F`` and the statements that call it lane by lane (the fallback)."""
    cg = ca.CodeGenerator("fte_cl_lane.c", {"with_header": False, "prefix": "fte_lane_"})
    nin = F.n_in()
    npar = F.nnz_in(3) if nin > 3 else 0
    G = ca.Function("fte_lane_f", [F.sx_in(i) for i in range(nin)], F.call([F.sx_in(i) for i in range(nin)]))
    cg.add(G)
    nout = G.n_out()
    ns, nw, nrec, ninc = F.size1_in(0), F.size1_in(1), F.size1_out(1), F.size1_out(2)
    npm = F.size1_out(3) if nout > 3 else 0
    lines = [
        f"  const double *arg[{max(G.sz_arg(), 4)}]; double *res[{max(G.sz_res(), 4)}];",
        f"  long long iw[{max(G.sz_iw(), 1)}]; double wk[{max(G.sz_w(), 1)}];",
        f"  double a0[{max(ns, 1)}], a1[{max(nw, 1)}], r0[{max(ns, 1)}], r1[{max(nrec, 1)}], r2[{max(ninc, 1)}], "
        f"r3[{max(npm, 1)}], pa[{max(npar, 1)}];",
        "  int l, j;",
        f"  for (j = 0; j < {npar}; ++j) pa[j] = par[j][0];",
        "  arg[0] = a0; arg[1] = a1; arg[2] = sh; arg[3] = pa; res[0] = r0; res[1] = r1; res[2] = r2; res[3] = r3;",
        "  for (l = 0; l < V; ++l) {",
        f"    for (j = 0; j < {ns}; ++j) a0[j] = st[j][l];",
        "    a1[0] = dw[l];",
        f"    for (j = 1; j < {nw}; ++j) a1[j] = j <= {ld} ? dd[j - 1][l] : dv[j - 1 - {ld}][l];",
        "    fte_lane_f((const casadi_real **)arg, res, (casadi_int *)iw, wk, 0);",
        f"    for (j = 0; j < {ns}; ++j) nx[j][l] = r0[j];",
        f"    if (recnow) for (j = 0; j < {nrec}; ++j) rb[j][l] = r1[j];",
        f"    for (j = 0; j < {ninc}; ++j) acc[j][l] += r2[j];",
        f"    for (j = 0; j < {npm}; ++j) pm[j][l] = r3[j];",
        "  }",
    ]
    return cg.dump(), lines


def _driver(exact: bool, ld: int, nv: int = 0) -> dict[str, str]:
    """The parts of the sample loop that differ between the modes. Exact: the random numbers drawn
    lane by lane, the divergence check lane by lane, the next state copied. Fast: the same uniforms
    computed on integer lane vectors, the normal's tails on the lane vector (through the vector
    ``log``, when any lane needs them; each lane keeps its own), the check as lane masks, the state
    buffers swapped. ``nv`` standard normals of the measurement noise follow the unknown inputs
    (counters ``k NSLOT + 2 + ld + j``)."""
    bc = lambda c: f"FTE_BC({c!r})"  # noqa: E731
    if exact:

        def normal(dest: str, counter: str, ind: str) -> str:
            return f"""{ind}{{  /* N by AS 241 (_rng.py): the central formula for 8 paths at once, the tail by path */
{ind}  double p[V] FTE_AL;
{ind}  fte_vd q, q_r;
{ind}  for (l = 0; l < V; ++l) p[l] = fte_p01(key[l], {counter});
{ind}  q = FTE_LD(p) - FTE_BC(0.5);
{ind}  q_r = FTE_BC(0.180625) - q * q;
{ind}  FTE_ST({dest}, {rng.central_c("q", "q_r", bc)});
{ind}  for (l = 0; l < V; ++l)
{ind}    if (!(fabs(p[l] - 0.5) <= {rng.TAIL!r})) {dest}[l] = fte_ndtri_tail(p[l]);
{ind}}}
"""

        noise = (
            (f"        for (j = 0; j < {nv}; ++j)\n" + normal("dv[j]", f"cb + {2 + ld} + j", "        "))
            if nv
            else ""
        )
        return {
            "decl": "  double st[NS][V] FTE_AL, nx[NS][V] FTE_AL, acc[NINC][V] FTE_AL, rb[NREC][V] FTE_AL, "
            "pm[NPM][V] FTE_AL, dw[V] FTE_AL, dd[LD][V] FTE_AL, dv[NV][V] FTE_AL;",
            "init": "",
            "rand": f"""      {{  /* dW = sqrt(dt) N */
{normal("dw", "cb + 1", "        ")}        for (l = 0; l < V; ++l) dw[l] = sqdt * dw[l];
        for (j = 0; j < {ld}; ++j)
          for (l = 0; l < V; ++l) dd[j][l] = damp * (2.0 * fte_u01(key[l], cb + 2 + j) - 1.0);
{noise}      }}
""",
            "after": """      for (j = 0; j < (int)(sizeof(XS) / sizeof(XS[0])); ++j)
        for (l = 0; l < V; ++l)
          if (div[l] < 0 && !(fabs(st[XS[j]][l]) <= bound)) div[l] = k;
      for (j = 0; j < NS; ++j)
        for (l = 0; l < V; ++l) st[j][l] = nx[j][l];
""",
            "final": "",
        }
    h = rng._c_horner
    dd = "".join(
        f"        FTE_ST(dd[{j}], FTE_BC(damp) * (FTE_BC(2.0) * fte_u01v(kv, cb + {2 + j}) - FTE_BC(1.0)));\n"
        for j in range(ld)
    )

    def normal_v(dest: str, counter: str, ind: str) -> str:
        return f"""{ind}{{  /* N by AS 241 (_rng.py): the same uniforms, drawn on integer lane vectors */
{ind}  fte_vd p = fte_p01v(kv, {counter}), q, q_r;
{ind}  q = p - FTE_BC(0.5);
{ind}  q_r = FTE_BC(0.180625) - q * q;
{ind}  FTE_ST({dest}, {rng.central_c("q", "q_r", bc)});
{ind}  {{  /* the tails on the lane vector, when any lane needs them: each lane selects its own */
{ind}    fte_vl tl = ~(fte_vl)(FTE_ABS(q) <= FTE_BC({rng.TAIL!r}));
{ind}    long long any = 0;
{ind}    for (l = 0; l < V; ++l) any |= tl[l];
{ind}    if (any) {{
{ind}      fte_vd lg = fte_v_log(FTE_SEL(q < FTE_BC(0.0), p, FTE_BC(1.0) - p)), rr, r1, r2, v;
{ind}      for (l = 0; l < V; ++l) rr[l] = sqrt(-lg[l]);
{ind}      r1 = rr - FTE_BC(1.6);
{ind}      r2 = rr - FTE_BC(5.0);
{ind}      v = FTE_SEL(rr <= FTE_BC(5.0), {h(rng._C, "r1", bc)} / {h(rng._D, "r1", bc)},
{ind}                  {h(rng._E, "r2", bc)} / {h(rng._F, "r2", bc)});
{ind}      v = FTE_SEL(q < FTE_BC(0.0), -v, v);
{ind}      FTE_ST({dest}, FTE_SEL(tl, v, FTE_LD({dest})));
{ind}    }}
{ind}  }}
{ind}}}
"""

    noise = (
        (f"        for (j = 0; j < {nv}; ++j)\n" + normal_v("dv[j]", f"cb + {2 + ld} + j", "        "))
        if nv
        else ""
    )
    return {
        "decl": "  double bufa[NS][V] FTE_AL, bufb[NS][V] FTE_AL, (*st)[V] = bufa, (*nx)[V] = bufb, (*tp)[V];\n"
        "  double acc[NINC][V] FTE_AL, rb[NREC][V] FTE_AL, pm[NPM][V] FTE_AL, dw[V] FTE_AL, dd[LD][V] FTE_AL, "
        "dv[NV][V] FTE_AL;\n"
        "  fte_vu kv;\n  fte_vl dv_;",
        "init": "    for (l = 0; l < V; ++l) kv[l] = key[l];\n    dv_ = (fte_vl)FTE_BC(0.0) - 1;\n",
        "rand": f"""      {{  /* dW = sqrt(dt) N */
{normal_v("dw", "cb + 1", "        ")}        FTE_ST(dw, FTE_BC(sqdt) * FTE_LD(dw));
{dd}{noise}      }}
""",
        "after": """      {  /* the first sample at which a plant state is NaN, infinite or beyond the bound, per lane */
        fte_vl bad = (fte_vl)FTE_BC(0.0), m;
        for (j = 0; j < (int)(sizeof(XS) / sizeof(XS[0])); ++j)
          bad |= ~(fte_vl)(FTE_ABS(FTE_LD(st[XS[j]])) <= FTE_BC(bound));
        m = bad & (dv_ < 0);
        dv_ = (dv_ & ~m) | (((fte_vl)FTE_BC(0.0) + k) & m);
      }
      tp = st; st = nx; nx = tp;
""",
        "final": "    for (l = 0; l < V; ++l) div[l] = dv_[l];\n",
    }


def emit(F: ca.Function, x_slots: list[int], name: str = "fte_mc", *, casadi_c: bool = False, exact: bool = True,
         vmath: bool = True, lanes: int = LANES, nv: int = 0) -> str:  # fmt: skip
    """C source of the lane engine of ``F: (state, w, sh[, par]) -> (next, rec, incr[, pm])``.

    ``w = [dW; d; v]``: ``v`` the last ``nv`` entries, standard normals of the measurement noise.
    ``par`` (optional): numbers fixed for the whole run (a design's), read by the engine, not compiled in.
    ``pm`` (optional): per-sample values summed over the paths (``PM``, samples x npm), in path order.

    ``x_slots``: the entries of ``state`` that are plant states (checked for divergence).
    ``casadi_c``: call CasADi's generated C of ``F`` lane by lane instead of emitting lane vectors.
    ``exact=False``: the fast mode's source (compile it with :data:`FAST_FLAGS`): the C library
    functions of :data:`_VMATH` and the normal's tails one call per lane vector, through glibc's vector
    math library when ``vmath`` (link ``-lmvec``), else lane by lane.
    Raises :class:`UnsupportedOperation` on an operation outside the emitter's tables."""
    if not F.is_a("SXFunction"):
        F = F.expand()
    ns, nw, nsh = F.size1_in(0), F.size1_in(1), F.size1_in(2)
    nrec, ninc = F.size1_out(1), F.size1_out(2)
    npm = F.size1_out(3) if F.n_out() > 3 else 0
    npar = F.nnz_in(3) if F.n_in() > 3 else 0
    ld = nw - 1 - nv
    head, body = _casadi_body(F, ld) if casadi_c else ("", _body(F, exact, ld))
    vm = ""
    if not exact:
        names = _op_names()
        used = {names.get(F.instruction_id(k)) for k in range(F.n_instructions())} if not casadi_c else set()
        vm = (
            "\n"
            + _vmath_prelude({_VMATH[o] for o in used if o in _VMATH} | {"log"}, vmath)
            + "\n"
            + _fast_rng(lanes)
        )
    xs = ", ".join(str(j) for j in x_slots) or "0"
    nslot = 1 + ld + nv
    drv = _driver(exact, ld, nv)
    return f"""/* generated by fte_casadi.sim._vector from a CasADi Function: do not edit */
{head}
#include <math.h>
#include <stdint.h>
#define V {lanes}
#define NS {ns}
#define NREC {max(nrec, 1)}
#define NINC {max(ninc, 1)}
#define NSH {nsh}
#define LD {max(ld, 1)}
#define NV {max(nv, 1)}
#define NPM {max(npm, 1)}
#define NPAR {max(npar, 1)}
#define FTE_AL __attribute__((aligned({8 * lanes})))
{_prelude(lanes)}{vm}
{rng.C_SOURCE}
static const int XS[] = {{{xs}}};
/* not inlined into the sample loop: inlined, gcc hoisted the loop-invariant loads of the parameters and its register
   allocator took 8.6 s over the quadruple tank's calibration engine (1.6 s not inlined; the manipulator's engine
   5.4 s against 1.7 s); the run is as fast either way (one call per sample and lane vector) */
static __attribute__((noinline)) void fte_sample(double st[NS][V], double nx[NS][V], double acc[NINC][V], double rb[NREC][V],
                       double pm[NPM][V], const double *sh, const double *dw, double dd[LD][V], double dv[NV][V],
                       int recnow, const fte_vd *restrict par) {{
{chr(10).join(body)}
}}

/* paths [path0, path0 + npaths): state S0 (npaths x NS) -> S1; sums ACC (npaths x NINC) over samples
   0 .. nsamp - 1; REC (npaths x nrs x NREC) every `every` samples when REC is not NULL; DIV: first
   diverging sample or -1. SH: (nsamp x NSH) shared inputs. PM (nsamp x NPM, when not NULL): each per-sample
   value added up over the paths, in path order (the caller initialises it). PAR: the parameters (a design's
   numbers). Random numbers: _rng.py. */
void {name}(long npaths, long path0, uint64_t seed, long nsamp, const double *SH, double sqdt, double damp,
            const double *S0, double *S1, double *ACC, long every, double *REC, long *DIV, double bound,
            double *PM, const double *PAR) {{
{drv["decl"]}
  uint64_t key[V];
  long div[V];
  long nrs = every > 0 ? (nsamp - 1) / every + 1 : 0;
  long c0, k;
  int l, j;
  fte_vd pv[NPAR];  /* the parameters, each broadcast to a lane vector once */
  for (j = 0; j < NPAR; ++j) pv[j] = FTE_BC(PAR[j]);
  for (c0 = 0; c0 < npaths; c0 += V) {{
    int nl = (npaths - c0) < V ? (int)(npaths - c0) : V;
    for (l = 0; l < V; ++l) {{
      long p = c0 + (l < nl ? l : 0);
      for (j = 0; j < NS; ++j) st[j][l] = S0[p * NS + j];
      for (j = 0; j < NINC; ++j) acc[j][l] = 0.0;
      for (j = 0; j < LD; ++j) dd[j][l] = 0.0;
      for (j = 0; j < NV; ++j) dv[j][l] = 0.0;
      key[l] = fte_key(seed, (uint64_t)(path0 + p));
      div[l] = -1;
    }}
{drv["init"]}    for (k = 0; k < nsamp; ++k) {{
      const double *sh = SH + k * NSH;
      int recnow = REC != 0 && k % every == 0;
      uint64_t cb = (uint64_t)k * {nslot};
{drv["rand"]}      fte_sample(st, nx, acc, rb, pm, sh, dw, dd, dv, recnow, pv);
      if (PM != 0 && {npm} > 0) {{
        for (j = 0; j < {npm}; ++j)
          for (l = 0; l < nl; ++l)
            PM[k * {npm} + j] += pm[j][l];
      }}
      if (recnow) {{
        for (l = 0; l < nl; ++l)
          for (j = 0; j < NREC; ++j) REC[((c0 + l) * nrs + k / every) * NREC + j] = rb[j][l];
      }}
{drv["after"]}    }}
{drv["final"]}    for (l = 0; l < nl; ++l) {{
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


def _compiled(src: str, cc: str, flags: tuple, libs: list[str], name: str) -> Path:
    """The shared library of ``src`` built with ``flags`` and ``libs``: from the cache (keyed by the
    source, compiler, flags, libraries and CPU), else compiled into it."""
    # the exact engine's key as before (its cached libraries stay valid)
    extra = "" if libs == ["-lm"] else " ".join(libs)
    key = hashlib.sha256((src + cc + " ".join(flags) + extra + _cpu_tag()).encode()).hexdigest()[:20]
    folder = cache_dir()
    lib = folder / f"{name}_{key}.so"
    if lib.exists():
        return lib
    folder.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        c = Path(tmp) / f"{name}.c"
        c.write_text(src)
        out = Path(tmp) / "lib.so"
        try:
            proc = subprocess.run([cc, *flags, "-o", str(out), str(c), *libs], capture_output=True, text=True,
                                  timeout=900)  # fmt: skip
        except (OSError, subprocess.TimeoutExpired) as exc:
            raise UnsupportedOperation(f"compiling the vectorised engine with {cc} failed: {exc}") from None
        if proc.returncode != 0:
            raise UnsupportedOperation(
                f"compiling the vectorised engine with {cc} failed: {proc.stderr[-1500:]}"
            )
        fd, tmp_lib = tempfile.mkstemp(dir=folder, suffix=".so.tmp")
        os.close(fd)
        shutil.copyfile(out, tmp_lib)
        os.replace(tmp_lib, lib)  # atomic: parallel workers may compile the same engine
    return lib


class VectorEngine:
    """The compiled lane engine of one closed-loop sample Function (compiled once, cached on disk).

    An operation the emitter does not know makes it fall back to CasADi's generated C lane by lane
    (``note`` says which; ``casadi_c=True`` asks for it); no C compiler, or a failed compile, raises
    :class:`UnsupportedOperation`. ``source_filter(str) -> str`` edits the C before it is compiled
    (for measurements only). ``exact=False``: the fast mode (:func:`emit`, :data:`FAST_FLAGS`; ``vmath``
    says whether it found glibc's vector math library). ``par``: the values of ``F``'s fourth input, when it has
    one (numbers fixed for a run: the same compiled engine serves other values)."""

    def __init__(self, F: ca.Function, x_slots: list[int], name: str = "fte_mc", *, casadi_c: bool | None = None,
                 source_filter=None, exact: bool = True, lanes: int = LANES, nv: int = 0, par=None):  # fmt: skip
        if not F.is_a("SXFunction"):
            F = F.expand()
        npar = F.nnz_in(3) if F.n_in() > 3 else 0
        par = np.zeros(0) if par is None else np.asarray(par, dtype=np.float64).ravel()
        if par.size != npar:
            raise ValueError(f"the engine's Function reads {npar} parameters; {par.size} given")
        self.par = np.ascontiguousarray(np.concatenate([par, [0.0]]))  # never empty: a valid pointer
        missing = unsupported(F)
        self.note = None
        self.exact = bool(exact)
        if casadi_c is None:
            casadi_c = bool(missing)
        elif missing and not casadi_c:
            raise UnsupportedOperation(
                f"the vectorised engine cannot emit CasADi operation(s) {', '.join(missing)}"
            )
        if missing:
            self.note = (
                f"the closed loop uses CasADi operation(s) {', '.join(missing)} that the vectorised engine cannot "
                "write as lane vectors: it runs CasADi's own generated C path by path (same numbers, slower)"
            )
        cc = find_compiler()
        if cc is None:
            raise UnsupportedOperation("no C compiler found (cc, gcc, clang or $CC)")
        # the fast mode links glibc's vector math library; where there is none, it calls the C library lane by lane
        tries = [True] if exact else [True, False]
        for k, vmath in enumerate(tries):
            src = emit(F, x_slots, name, casadi_c=casadi_c, exact=exact, vmath=vmath, lanes=lanes, nv=nv)
            if source_filter is not None:  # the benchmark's anatomy: the same engine with parts left out
                src = source_filter(src)
            flags = FLAGS if exact else FAST_FLAGS
            libs = ["-lm"] if exact or not vmath else ["-Wl,-z,defs", "-lmvec", "-lm"]
            try:
                lib = _compiled(src, cc, flags, libs, name)
                break
            except UnsupportedOperation:
                if k + 1 == len(tries):
                    raise
        self.vmath = not exact and vmath
        if not exact and not vmath:
            note = "the fast mode found no vector math library (glibc's libmvec): it calls the C library lane by lane"
            self.note = f"{self.note}; {note}" if self.note else note
        self.lib = ctypes.CDLL(str(lib))
        self.fn = getattr(self.lib, name)
        dp = ctypes.POINTER(ctypes.c_double)
        lp = ctypes.POINTER(ctypes.c_long)
        self.fn.argtypes = [ctypes.c_long, ctypes.c_long, ctypes.c_uint64, ctypes.c_long, dp, ctypes.c_double,
                            ctypes.c_double, dp, dp, dp, ctypes.c_long, dp, lp, ctypes.c_double, dp, dp]  # fmt: skip
        self.fn.restype = None
        self.ns, self.nrec, self.ninc, self.nsh = F.size1_in(0), F.size1_out(1), F.size1_out(2), F.size1_in(2)
        self.npm = F.size1_out(3) if F.n_out() > 3 else 0
        self.source = src

    def run(self, path0: int, S0: np.ndarray, seed: int, SH: np.ndarray, sqdt: float, damp: float,
            bound: float, every: int = 0, pm: bool = False):  # fmt: skip
        """Run paths ``path0 ..`` from states ``S0`` (paths, ns) over the samples of ``SH``.

        Returns ``(S1, ACC, DIV, REC)``; ``REC`` (paths, samples, nrec) only when ``every > 0``; with ``pm``
        also ``PM`` (samples, npm), each per-sample value summed over these paths in path order."""
        P, nsamp = S0.shape[0], SH.shape[0]
        S0 = np.ascontiguousarray(S0, dtype=np.float64)
        SH = np.ascontiguousarray(SH, dtype=np.float64)
        S1 = np.empty_like(S0)
        ACC = np.empty((P, self.ninc))
        DIV = np.empty(P, dtype=np.int_)
        REC = np.empty((P, (nsamp - 1) // every + 1, self.nrec)) if every > 0 else None
        PM = np.zeros((nsamp, self.npm)) if (pm and self.npm) else None
        dp = ctypes.POINTER(ctypes.c_double)
        self.fn(P, int(path0), ctypes.c_uint64(int(seed) & 0xFFFFFFFFFFFFFFFF), nsamp, SH.ctypes.data_as(dp),
                float(sqdt), float(damp), S0.ctypes.data_as(dp), S1.ctypes.data_as(dp), ACC.ctypes.data_as(dp),
                int(every), REC.ctypes.data_as(dp) if REC is not None else None,
                DIV.ctypes.data_as(ctypes.POINTER(ctypes.c_long)), float(bound),
                PM.ctypes.data_as(dp) if PM is not None else None, self.par.ctypes.data_as(dp))  # fmt: skip
        if pm:
            return S1, ACC, DIV, REC, PM
        return S1, ACC, DIV, REC
