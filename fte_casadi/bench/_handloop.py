"""The fast Monte Carlo mode against a hand-vectorised C loop over the same arithmetic.

:func:`hand_loop_c` writes the loop a C programmer writes for a Monte Carlo of one closed-loop sample
when speed is all that counts: the state of a block of paths in arrays with the paths innermost
(``S[j][p]``), one ``#pragma omp simd`` loop over the paths per sample whose body is the sample's
arithmetic as plain scalar C (the engine Function's CasADi instructions, one statement each) and the
same random numbers (the counter-based generator of :mod:`fte_casadi.sim._rng`, AS 241 with both tails
computed and selected, so nothing branches), compiled with ``-O3 -march=native -ffast-math
-fopenmp-simd``: GCC vectorises the path loop itself, contracts into fused multiply-adds and calls
glibc's vector math library (libmvec) for ``sin``/``log``. :func:`bench_fast` compiles it in the same
run, checks that it computes the engine's numbers (to rounding) and times it in one thread, best of
several repetitions, against the engine in its fast and exact modes on the same paths, one call of
``paths`` paths each.
"""

from __future__ import annotations

import ctypes
import re
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from fte_casadi._toolchain import find_compiler
from fte_casadi.sim import _rng as rng
from fte_casadi.sim._vector import _BINARY, _CALL, _VMATH, VectorEngine

__all__ = []  # public: docs/api.md

#: the hand loop's flags: everything allowed (reassociation, contraction, vector math library)
HAND_FLAGS = ("-O3", "-march=native", "-fno-math-errno", "-fno-trapping-math", "-ffp-contract=fast", "-fopenmp-simd",
              "-shared", "-fPIC")  # fmt: skip

#: scalar C of the operations (``{a}``, ``{b}`` the operands)
_SCALAR = {
    "OP_ASSIGN": "{a}", "OP_LIFT": "{a}", "OP_ADD": "{a} + {b}", "OP_SUB": "{a} - {b}", "OP_MUL": "{a} * {b}",
    "OP_DIV": "{a} / {b}", "OP_NEG": "-{a}", "OP_SQ": "{a} * {a}", "OP_TWICE": "2.0 * {a}", "OP_INV": "1.0 / {a}",
    "OP_LT": "({a} < {b} ? 1.0 : 0.0)", "OP_LE": "({a} <= {b} ? 1.0 : 0.0)", "OP_EQ": "({a} == {b} ? 1.0 : 0.0)",
    "OP_NE": "({a} != {b} ? 1.0 : 0.0)", "OP_NOT": "({a} == 0.0 ? 1.0 : 0.0)",
    "OP_AND": "({a} != 0.0 && {b} != 0.0 ? 1.0 : 0.0)", "OP_OR": "({a} != 0.0 || {b} != 0.0 ? 1.0 : 0.0)",
    "OP_IF_ELSE_ZERO": "({a} != 0.0 ? {b} : 0.0)", "OP_FABS": "fabs({a})", "OP_COPYSIGN": "copysign({a}, {b})",
    "OP_SIGN": "({a} < 0.0 ? -1.0 : ({a} > 0.0 ? 1.0 : {a}))", "OP_FMIN": "({a} < {b} || {b} != {b} ? {a} : {b})",
    "OP_FMAX": "({a} > {b} || {b} != {b} ? {a} : {b})",
}  # fmt: skip


def _statements(F: ca.Function) -> list[str]:
    names = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}
    out = []
    for k in range(F.n_instructions()):
        op = F.instruction_id(k)
        nm = names.get(op, str(op))
        ins, outs = list(F.instruction_input(k)), list(F.instruction_output(k))
        if op == ca.OP_INPUT:
            i, nz = ins
            src = f"S[{nz}][p]" if i == 0 else ("dw" if nz == 0 else f"dd{nz - 1}") if i == 1 else f"sh[{nz}]"
            src = f"par[{nz}]" if i == 3 else src
            out.append(f"w{outs[0]} = {src};")
        elif op == ca.OP_CONST:
            v = float(F.instruction_constant(k))
            out.append(f"w{outs[0]} = {v!r};" if np.isfinite(v) else f"w{outs[0]} = {'NAN' if v != v else ('INFINITY' if v > 0 else '-INFINITY')};")  # fmt: skip
        elif op == ca.OP_OUTPUT:
            i, nz = outs
            if i == 0:
                out.append(f"N[{nz}][p] = w{ins[0]};")
            elif i == 2:
                out.append(f"A[{nz}][p] += w{ins[0]};")
        elif nm in _SCALAR:
            b = f"w{ins[1]}" if len(ins) > 1 else ""
            out.append(f"w{outs[0]} = {_SCALAR[nm].format(a=f'w{ins[0]}', b=b)};")
        elif nm in _CALL:
            args = f"w{ins[0]}, w{ins[1]}" if nm in _BINARY else f"w{ins[0]}"
            out.append(f"w{outs[0]} = {_CALL[nm]}({args});")
        else:
            raise ValueError(f"the hand loop has no scalar C for CasADi operation {nm}")
    return out


def hand_loop_c(F: ca.Function, x_slots: list[int], block: int) -> str:
    """C of ``hand_mc`` (the engine's C interface without recording) for ``F: (state, w, sh[, par]) -> (next, rec,
    incr)``: blocks of ``block`` paths, samples outer, paths innermost in one ``omp simd`` loop."""
    ns, nw, nsh, ninc = F.size1_in(0), F.size1_in(1), F.size1_in(2), F.size1_out(2)
    ld = nw - 1
    work = ", ".join(f"w{i}" for i in range(max(F.sz_w(), 1)))
    h = rng._c_horner
    dds = "".join(
        f"    double dd{j} = damp * (2.0 * fte_u01(key[p], cb + {2 + j}) - 1.0);\n" for j in range(ld)
    )
    xs = " || ".join(f"!(fabs(S[{j}][p]) <= bound)" for j in x_slots) or "0"
    body = "\n    ".join(_statements(F))
    fns = sorted(set(_VMATH.values()) | {"log"})
    simd = "\n".join(
        f"#pragma omp declare simd notinbranch\ndouble {f}(double{', double' if f in ('pow', 'atan2', 'hypot') else ''});"
        for f in fns
    )
    return f"""/* a hand-vectorised Monte Carlo loop (fte_casadi/bench/_handloop.py): paths innermost */
#include <math.h>
#include <stdint.h>
#include <string.h>
#define B {block}
/* glibc's vector math library for the path loop: what <math.h> declares under -ffast-math */
{simd}
{rng.C_SOURCE}
void hand_mc(long npaths, long path0, uint64_t seed, long nsamp, const double *SH, double sqdt, double damp,
             const double *S0, double *S1, double *ACC, long *DIV, double bound, const double *par) {{
  static double SA[{ns}][B] __attribute__((aligned(64))), SB[{ns}][B] __attribute__((aligned(64)));
  static double A[{max(ninc, 1)}][B] __attribute__((aligned(64)));
  static uint64_t key[B] __attribute__((aligned(64)));
  static long div[B] __attribute__((aligned(64)));
  long b0, k;
  int p, j;
  for (b0 = 0; b0 < npaths; b0 += B) {{
    int nb = npaths - b0 < B ? (int)(npaths - b0) : B;
    double (*S)[B] = SA, (*N)[B] = SB, (*T)[B];
    for (p = 0; p < B; ++p) {{
      long q = b0 + (p < nb ? p : 0);
      for (j = 0; j < {ns}; ++j) S[j][p] = S0[q * {ns} + j];
      for (j = 0; j < {max(ninc, 1)}; ++j) A[j][p] = 0.0;
      key[p] = fte_key(seed, (uint64_t)(path0 + q));
      div[p] = -1;
    }}
    for (k = 0; k < nsamp; ++k) {{
      const double *sh = SH + k * {nsh};
      uint64_t cb = (uint64_t)k * {nw};
#pragma omp simd
      for (p = 0; p < B; ++p) {{
    double {work};
    double pr = fte_p01(key[p], cb + 1), q = pr - 0.5, r = 0.180625 - q * q;
    double c = {rng.central_c("q", "r")};
    double rt = sqrt(-log(q < 0.0 ? pr : 1.0 - pr)), r1 = rt - 1.6, r2 = rt - 5.0;
    double v = rt <= 5.0 ? {h(rng._C, "r1", repr)} / {h(rng._D, "r1", repr)} : {h(rng._E, "r2", repr)} / {h(rng._F, "r2", repr)};
    double dw = sqdt * (fabs(q) <= {rng.TAIL!r} ? c : (q < 0.0 ? -v : v));
{dds}    if (div[p] < 0 && ({xs})) div[p] = k;
    {body}
      }}
      T = S; S = N; N = T;
    }}
    for (p = 0; p < nb; ++p) {{
      for (j = 0; j < {ns}; ++j) S1[(b0 + p) * {ns} + j] = S[j][p];
      for (j = 0; j < {max(ninc, 1)}; ++j) ACC[(b0 + p) * {max(ninc, 1)} + j] = A[j][p];
      DIV[b0 + p] = div[p];
    }}
  }}
}}
"""


def _compile_hand(src: str, folder: Path, flags: tuple) -> tuple[ctypes.CDLL, bool]:
    """The hand loop's library, and whether GCC vectorised its path loop (``-fopt-info-vec``)."""
    cc = find_compiler()
    if cc is None:
        raise RuntimeError("no C compiler found")
    c = folder / "hand.c"
    c.write_text(src)
    obj, out = folder / "hand.o", folder / "hand.so"
    # compiled and linked apart: linking with -ffast-math would add crtfastmath.o, which switches the
    # whole process to flush-to-zero when the library is loaded
    proc = subprocess.run([cc, *(f for f in flags if f != "-shared"), "-fopt-info-vec-optimized", "-c", "-o", str(obj),
                           str(c)], capture_output=True, text=True, timeout=900)  # fmt: skip
    if proc.returncode == 0:
        link = subprocess.run([cc, "-shared", "-o", str(out), str(obj), "-lmvec", "-lm"], capture_output=True,
                              text=True, timeout=900)  # fmt: skip
        if link.returncode != 0:
            proc = link
    if proc.returncode != 0:
        raise RuntimeError(f"compiling the hand loop failed: {proc.stderr[-1500:]}")
    first = src[: src.index("#pragma omp simd")].count("\n") + 1  # the path loop's lines
    last = src[: src.index("T = S; S = N;")].count("\n") + 1
    done = {int(m) for m in re.findall(r"hand\.c:(\d+):\d+: optimized: loop vectorized", proc.stderr)}
    return ctypes.CDLL(str(out)), any(first <= k <= last for k in done)


def bench_fast(prep, paths: int = 64, seed: int = 0, repeats: int = 15, blocks=(8, 16, 64)) -> dict:
    """One thread, ``paths`` paths of the scenario of ``prep`` (a :class:`fte_casadi.sim._engine.Prepared`):
    nanoseconds per path-step of the engine in its fast and exact modes and of the hand loop, one call
    of all ``paths`` each, best of ``repeats``, interleaved (all see the same load of a shared machine),
    timed by the thread's CPU time (``time.thread_time``: the slices that other jobs take are not
    counted; what they do to the caches is).

    The hand loop is compiled twice, each with its fastest block size of ``blocks``: ``hand`` with the
    fast mode's semantics (:data:`HAND_FLAGS`: contraction, vector math library, IEEE otherwise) and
    ``hand_fast_math`` with ``-ffast-math`` on top (reassociation, no NaN or infinities: the divergence
    check may miss a NaN). ``ratio_fast_vs_hand`` = the hand loop's time / the fast engine's (1: as fast)."""
    F = prep.engine_function
    xs = [r * prep.lay.run_state + j for r in range(3) for j in range(prep.lay.n)]
    fast = VectorEngine(F, xs, name="fte_mc", exact=False, par=prep.par)
    exact = prep.engine if prep.engine.exact else VectorEngine(F, xs, name="fte_mc", par=prep.par)
    S0 = prep.initial_states(np.arange(paths), seed)
    nsamp = prep.SH.shape[0]
    steps = paths * nsamp
    dp = ctypes.POINTER(ctypes.c_double)
    bound = float(prep.scenario.divergence_bound)
    variants = {"hand": HAND_FLAGS, "hand_fast_math": (*HAND_FLAGS, "-ffast-math")}
    with tempfile.TemporaryDirectory(prefix="fte_hand_") as tmp:
        hands, vectorised = {}, {}
        for v, flags in variants.items():
            for b in blocks:
                folder = Path(tmp) / f"{v}_{b}"
                folder.mkdir()
                hands[v, b], vectorised[f"{v}_{b}"] = _compile_hand(hand_loop_c(F, xs, b), folder, flags)

        def run_hand(lib):
            S1 = np.empty_like(S0)
            ACC = np.empty((paths, max(F.size1_out(2), 1)))
            DIV = np.empty(paths, dtype=np.int_)
            lib.hand_mc(ctypes.c_long(paths), ctypes.c_long(0), ctypes.c_uint64(seed), ctypes.c_long(nsamp),
                        prep.SH.ctypes.data_as(dp), ctypes.c_double(prep.sqdt), ctypes.c_double(prep.damp),
                        S0.ctypes.data_as(dp), S1.ctypes.data_as(dp), ACC.ctypes.data_as(dp),
                        DIV.ctypes.data_as(ctypes.POINTER(ctypes.c_long)), ctypes.c_double(bound),
                        fast.par.ctypes.data_as(dp))  # fmt: skip
            return S1, ACC

        def run_engine(eng):
            S1, ACC, _, _ = eng.run(0, S0, seed, prep.SH, prep.sqdt, prep.damp, bound, 0)
            return S1, ACC

        def timed(fn) -> float:  # this thread's CPU time: the time slices other jobs take are not counted
            t0 = time.thread_time()
            fn()
            return (time.thread_time() - t0) / steps * 1e9

        t_fast, t_exact, t_hand = [], [], {k: [] for k in hands}
        for _ in range(max(1, int(repeats))):
            t_fast.append(timed(lambda: run_engine(fast)))
            t_exact.append(timed(lambda: run_engine(exact)))
            for k, lib in hands.items():
                t_hand[k].append(timed(lambda lib=lib: run_hand(lib)))
        S1f, _ = run_engine(fast)
        scale = np.maximum(np.max(np.abs(S1f), axis=0), 1e-300)
        best, diff = {}, {}
        for v in variants:
            b = min(blocks, key=lambda b, v=v: min(t_hand[v, b]))
            best[v] = (b, min(t_hand[v, b]))
            diff[v] = float(np.max(np.abs(run_hand(hands[v, b])[0] - S1f) / scale))
    tf, te = min(t_fast), min(t_exact)
    return {
        "paths": paths, "threads": 1, "samples": nsamp, "repeats": int(repeats),
        "fast_ns_per_path_step": tf, "exact_ns_per_path_step": te,
        "hand_ns_per_path_step": best["hand"][1], "hand_block": best["hand"][0], "hand_flags": " ".join(HAND_FLAGS),
        "hand_fast_math_ns_per_path_step": best["hand_fast_math"][1],
        "hand_fast_math_block": best["hand_fast_math"][0],
        "ratio_fast_vs_hand": best["hand"][1] / tf, "ratio_exact_vs_hand": best["hand"][1] / te,
        "ratio_fast_vs_hand_fast_math": best["hand_fast_math"][1] / tf,
        "hand_ns_by_variant_and_block": {f"{v}_{b}": min(t) for (v, b), t in t_hand.items()},
        "hand_path_loop_vectorised": vectorised, "hand_max_rel_diff_final_state": diff,
        "fast_ns_all_repeats": t_fast, "exact_ns_all_repeats": t_exact,
    }  # fmt: skip
