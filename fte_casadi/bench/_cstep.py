"""Speed and size of the generated step, measured.

For each design :func:`bench_c_step` reports

- ``c_ns``: nanoseconds per ``fte_NAME_step`` call, from a C timing loop (``clock_gettime``,
  ``-O2``, the strict flags) over varying measurements; best of several repetitions;
- ``hand_ns``: the same arithmetic written as plain C loops over the design's dense matrices
  (the expanded sum over rules of docs/method.md, "The discrete step"; memberships by the same CasADi-generated scheduling
  function), generated here from the design as a baseline, and ``ratio = c_ns / hand_ns``;
- ``casadi_us``: microseconds per call of the same step as a CasADi Function from Python;
- ``state_bytes`` (``sizeof(fte_NAME_state)``), the README's constant-data counts, and the
  ``text``/``data``/``bss`` sizes of the generated objects when binutils' ``size`` is found
  (``data`` and ``bss`` are 0: the code has no mutable globals).

The timing main also checks that the hand-written baseline computes the same numbers (``hand_max_diff``).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import tempfile
import time
from pathlib import Path

import casadi as ca
import numpy as np

from fte_casadi.codegen import _build as build
from fte_casadi.codegen._generate import _void_unused, c_name, default_sample_time, generate_c, memory_report
from fte_casadi.design import Design
from fte_casadi.step import step_function

__all__ = ["bench_c_step"]  # public: docs/api.md


def _arr(name: str, a) -> str:
    a = np.atleast_1d(np.asarray(a, dtype=float)).ravel()
    return (
        f"static const fte_real {name}[{max(1, a.size)}] = {{" + ", ".join(f"{v:.17g}" for v in a) + "};\n"
        if a.size
        else f"static const fte_real {name}[1] = {{0}};\n"
    )


def hand_written_c(design: Design, sample_time: float) -> str:
    """Plain C of the step (dense loops, expanded sum over rules), for the speed baseline."""
    d = design.dims
    n, m, p, lf, r, nbar = (int(getattr(d, k)) for k in ("n", "m", "p", "lf", "r", "nbar"))
    T = np.asarray(design.T)
    Cbar = np.hstack([design.C, np.zeros((p, lf)), design.Df])
    gain = float(design.params.delta) + float(design.params.epsilon)
    src = [f"/* hand-written baseline, n={n} m={m} p={p} lf={lf} r={r} */\n", '#include "hand.h"\n']
    src.append("int hand_sched(const fte_real **arg, fte_real **res, int *iw, fte_real *w, int mem);\n")
    for k, M in (
        ("H", design.H),
        ("NN", design.N),
        ("CB", Cbar),
        ("KF", design.Kf),
        ("DF", design.Df),
        ("LS", design.Ls),
    ):
        src.append(_arr(k, M))
    src.append(_arr("UREF", design.u_ref))
    for i in range(r):
        lm = design.local_models[i]
        Bbar = np.vstack([lm.B, np.zeros((2 * lf, m))])
        abar = np.concatenate([lm.a.ravel(), np.zeros(2 * lf)])
        src.append(_arr(f"R{i}", design.R[i]))
        src.append(_arr(f"TB{i}", T @ Bbar))
        src.append(_arr(f"LY{i}", np.asarray(design.L1[i]) + np.asarray(design.L2[i])))
        src.append(_arr(f"TA{i}", T @ abar))
        src.append(_arr(f"K{i}", design.K[i]))
    body = f"""
void hand_step(fte_real *z, const fte_real *y, fte_real *u, fte_real *xb, fte_real *yc) {{
  fte_real h[{r}], s[{lf}], us[{lf}], e[{p}], rhs[{nbar}], t[{nbar}];
  const fte_real *a[2];
  fte_real *o[1];
  int i, j;
  for (i = 0; i < {nbar}; ++i) {{ xb[i] = z[i]; for (j = 0; j < {p}; ++j) xb[i] += H[i*{p}+j]*y[j]; }}
  a[0] = y; a[1] = xb; o[0] = h;
  hand_sched(a, o, 0, 0, 0);
  for (i = 0; i < {p}; ++i) {{ e[i] = y[i]; for (j = 0; j < {nbar}; ++j) e[i] -= CB[i*{nbar}+j]*xb[j]; }}
  for (i = 0; i < {lf}; ++i) {{
    s[i] = 0; for (j = 0; j < {p}; ++j) s[i] += NN[i*{p}+j]*e[j];
    us[i] = (fte_real){gain!r} * (s[i] > 0 ? 1 : s[i] < 0 ? -1 : 0);
  }}
  for (i = 0; i < {m}; ++i) {{
    u[i] = UREF[i];
    for (j = 0; j < {lf}; ++j) u[i] += KF[i*{lf}+j]*xb[{n + lf}+j];
  }}
"""
    for i in range(r):
        body += f"  for (i = 0; i < {m}; ++i) {{ fte_real acc = 0; for (j = 0; j < {n}; ++j) acc += K{i}[i*{n}+j]*xb[j]; u[i] += h[{i}]*acc; }}\n"
    if design.input_limits is not None:  # the same clipping as the generated step
        for k, (lo, hi) in enumerate(np.asarray(design.input_limits, float)):
            if np.isfinite(lo):
                body += f"  if (u[{k}] < (fte_real){float(lo)!r}) u[{k}] = (fte_real){float(lo)!r};\n"
            if np.isfinite(hi):
                body += f"  if (u[{k}] > (fte_real){float(hi)!r}) u[{k}] = (fte_real){float(hi)!r};\n"
    body += f"""  for (i = 0; i < {p}; ++i) {{ yc[i] = y[i]; for (j = 0; j < {lf}; ++j) yc[i] -= DF[i*{lf}+j]*xb[{n + lf}+j]; }}
  for (i = 0; i < {nbar}; ++i) {{ rhs[i] = 0; for (j = 0; j < {lf}; ++j) rhs[i] += LS[i*{lf}+j]*us[j]; }}
"""
    for i in range(r):
        body += f"""  for (i = 0; i < {nbar}; ++i) {{
    t[i] = TA{i}[i];
    for (j = 0; j < {nbar}; ++j) t[i] += R{i}[i*{nbar}+j]*z[j];
    for (j = 0; j < {m}; ++j) t[i] += TB{i}[i*{m}+j]*u[j];
    for (j = 0; j < {p}; ++j) t[i] += LY{i}[i*{p}+j]*y[j];
    rhs[i] += h[{i}]*t[i];
  }}
"""
    body += f"  for (i = 0; i < {nbar}; ++i) z[i] += (fte_real){float(sample_time)!r}*rhs[i];\n}}\n"
    return "".join(src) + body


_TIMING_MAIN = """\
#define _POSIX_C_SOURCE 199309L
#include <math.h>
#include <stdio.h>
#include <time.h>
#include "fte_{name}.h"
#include "hand.h"

static double now(void) {{
  struct timespec t;
  clock_gettime(CLOCK_MONOTONIC, &t);
  return (double)t.tv_sec * 1e9 + (double)t.tv_nsec;
}}

int main(void) {{
  static const double y0[{ny}] = {{{y0}}};
  static fte_real ys[64][{ny}];
  fte_{name}_state s;
  fte_real u[{nu}], xb[{nxbar}], yc[{ny}], zh[{nxbar}], uh[{nu}], xbh[{nxbar}], ych[{ny}];
  volatile double sink = 0;
  double best_gen = 1e300, best_hand = 1e300, diff = 0, t0, t1;
  long k, N = {iters};
  int rep, i;
  for (k = 0; k < 64; ++k)
    for (i = 0; i < {ny}; ++i) ys[k][i] = (fte_real)(y0[i] * (1.0 + 0.01 * sin(0.3 * (double)k + i)) + 0.01 * cos(0.2 * (double)k));
  fte_{name}_init(&s, 0);
  for (i = 0; i < {nxbar}; ++i) zh[i] = 0;
  for (k = 0; k < 200; ++k) {{
    fte_{name}_step(&s, ys[k & 63], u, xb, yc);
    hand_step(zh, ys[k & 63], uh, xbh, ych);
    for (i = 0; i < {nu}; ++i) diff = fmax(diff, fabs((double)(u[i] - uh[i])));
    for (i = 0; i < {nxbar}; ++i) diff = fmax(diff, fabs((double)(s.z[i] - zh[i])));
  }}
  for (rep = 0; rep < {reps}; ++rep) {{
    t0 = now();
    for (k = 0; k < N; ++k) {{ fte_{name}_step(&s, ys[k & 63], u, xb, yc); sink += u[0]; }}
    t1 = now();
    if ((t1 - t0) / (double)N < best_gen) best_gen = (t1 - t0) / (double)N;
    t0 = now();
    for (k = 0; k < N; ++k) {{ hand_step(zh, ys[k & 63], uh, xbh, ych); sink += uh[0]; }}
    t1 = now();
    if ((t1 - t0) / (double)N < best_hand) best_hand = (t1 - t0) / (double)N;
  }}
  printf("%.3f %.3f %d %.3e %g\\n", best_gen, best_hand, (int)sizeof(s), diff, (double)sink * 0.0);
  return 0;
}}
"""


def _object_sizes(folder: Path, cc: str) -> dict | None:
    size = shutil.which("size")
    if size is None:
        return None
    out = {"text": 0, "data": 0, "bss": 0}
    for c in sorted(folder.glob("fte_*.c")):
        obj = folder / (c.stem + ".o")
        subprocess.run(
            [cc, *build.STRICT_FLAGS, "-c", str(c), "-o", str(obj)], check=True, capture_output=True
        )
        line = subprocess.run(
            [size, str(obj)], capture_output=True, text=True, check=True
        ).stdout.splitlines()[1]
        text, data, bss = (int(v) for v in line.split()[:3])
        out["text"] += text
        out["data"] += data
        out["bss"] += bss
    return out


def _casadi_call_s(fn, z: np.ndarray, y0: np.ndarray) -> float:
    """Seconds per call of the step Function from Python with numpy arrays, as the simulator would per sample
    (best of three runs of 2000 calls)."""
    calls = 2000
    best = np.inf
    for _ in range(3):
        t0 = time.perf_counter()
        for _k in range(calls):
            fn(z, y0)
        best = min(best, (time.perf_counter() - t0) / calls)
    return best


def _hand_sources(design: Design, folder: Path, sample_time: float, real: str, name: str) -> Path:
    """``folder/hand``: the hand-written step (:func:`hand_written_c`), its header, and CasADi's C of the
    scheduling function it calls."""
    hand = folder / "hand"
    hand.mkdir()
    (hand / "hand.h").write_text(
        f'#include "fte_{name}.h"\nvoid hand_step(fte_real *z, const fte_real *y, fte_real *u, fte_real *xb, fte_real *yc);\n'
    )
    (hand / "hand.c").write_text(hand_written_c(design, sample_time))
    sched = design.scheduling_function()
    sched = ca.Function(
        "hand_sched", [sched.sx_in(0), sched.sx_in(1)], sched.call([sched.sx_in(0), sched.sx_in(1)])
    )
    gen = ca.CodeGenerator(
        "hand_sched.c",
        {"prefix": "hand_cs", "casadi_real": real, "casadi_int": "int", "with_header": False},
    )
    gen.add(sched)
    gen.generate(str(hand) + os.sep)
    (hand / "hand_sched.c").write_text(_void_unused((hand / "hand_sched.c").read_text()))
    return hand


def bench_c_step(
    design: Design,
    *,
    sample_time: float | None = None,
    real: str = "double",
    iters: int = 200_000,
    reps: int = 5,
) -> dict:
    """Measure one design's generated step (see the module docstring for the fields)."""
    cc = build.find_compiler()
    sample_time = default_sample_time(design) if sample_time is None else sample_time
    name = c_name(design.plant)
    fn = step_function(design, sample_time)
    y0 = np.asarray(design.C) @ (
        np.full(design.dims.n, 0.1) if design.x_ref is None else np.asarray(design.x_ref)
    )
    result = {
        "plant": design.plant,
        "ts": sample_time,  # the bench document's key (kept)
        "real": real,
        "casadi_us": _casadi_call_s(fn, np.zeros(design.nz), y0) * 1e6,  # z and the gate's state
        **memory_report(design, sample_time=sample_time, real=real),
    }
    if cc is None:
        result["c_ns"] = None
        result["note"] = "no C compiler found: C timings not measured"
        return result
    with tempfile.TemporaryDirectory(prefix="fte_bench_") as tmp:
        folder = Path(tmp)
        generate_c(design, folder, sample_time=sample_time, real=real)
        result["objects"] = _object_sizes(folder, cc)
        hand = _hand_sources(design, folder, sample_time, real, name)
        main = hand / "timing_main.c"
        main.write_text(
            _TIMING_MAIN.format(
                name=name,
                ny=int(design.dims.p),
                nu=int(design.dims.m),
                nxbar=design.nbar,
                y0=", ".join(f"{v:.17g}" for v in y0),
                iters=iters,
                reps=reps,
            )
        )
        exe = build.compile_program(
            folder,
            main,
            folder / "timing",
            extra_flags=[f"-I{hand}"],
            extra_sources=[hand / "hand.c", hand / "hand_sched.c"],
        )
        gen_ns, hand_ns, state_bytes, diff, _ = (
            float(v) for v in build.run_program(exe, timeout=300).split()
        )
    result.update(
        c_ns=gen_ns,
        hand_ns=hand_ns,
        ratio=gen_ns / hand_ns,
        sizeof_state=int(state_bytes),
        hand_max_diff=diff,
    )
    return result
