"""The generated C recovers from bad measurements, with floating-point traps and sanitizers on.

A harness ``main`` (below) enables ``FE_DIVBYZERO | FE_INVALID | FE_OVERFLOW`` traps and runs the step of
a built-in plant twice: once on sane measurements only, once with NaN, +-infinity, +-DBL_MAX (one entry
or all) between them. Each bad sample must return non-zero and leave the state byte for byte as it was;
the outputs of the two runs must then be identical (recovery). ``init`` and ``init_from_y`` refuse such an
initial state (``z0``, ``xbar0``) with 1 or 3 and leave the state as it was. Denormal and zero measurements must go
through without a trap. Compiled ``-O0 -g -fsanitize=address,undefined,float-divide-by-zero
-fno-sanitize-recover=all``: any 0/0 (even in a discarded branch), overflow or undefined behaviour stops
the run. The float variant must compile with ``-Wdouble-promotion -Werror`` and pass the same harness,
and ``-ffast-math`` must not remove the NaN check.
"""

from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.codegen._generate import BUILTIN_DIRS, c_name, generate_c
from fte_casadi.design import Design

GENERATED = Path(__file__).resolve().parents[1] / "generated"
CC = shutil.which("cc") or shutil.which("gcc")
CONTRACT = ["-std=c99", "-Wall", "-Wextra", "-Werror", "-pedantic"]
SANITIZE = ["-O0", "-g", "-fsanitize=address,undefined,float-divide-by-zero", "-fno-sanitize-recover=all"]

HARNESS = r"""
#define _GNU_SOURCE
#include <fenv.h>
#include <float.h>
#include <math.h>
#include <stdio.h>
#include <string.h>
#include "fte_@name@.h"

#define NY FTE_@NAME@_NY
#define NU FTE_@NAME@_NU
#define NX FTE_@NAME@_NXBAR
#define STEPS 12
#ifdef HARNESS_FLOAT
#define BIG FLT_MAX
#define TINY 1e-40f  /* a float denormal */
#else
#define BIG DBL_MAX
#define TINY 4.9e-324 /* the smallest double denormal */
#endif

static const fte_real Y0[NY] = {@y0@};

static void sane(int k, fte_real *y) {
  int i;
  for (i = 0; i < NY; ++i) y[i] = Y0[i] + (fte_real)(0.01 * sin(0.7 * k + i));
}

/* 0 when the step refused y (non-zero return) and the state is byte for byte the same */
static int refused(fte_@name@_state *s, const fte_real *y) {
  fte_@name@_state before;
  fte_real u[NU], xb[NX], yc[NY];
  int rc;
  memcpy(&before, s, sizeof before);
  memset(u, 0x5a, sizeof u);
  rc = fte_@name@_step(s, y, u, xb, yc);
  if (rc == 0) { printf("accepted a bad sample\n"); return 1; }
  if (memcmp(&before, s, sizeof before) != 0) { printf("state changed (rc %d)\n", rc); return 1; }
  return 0;
}

int main(void) {
  fte_@name@_state a, b, c;
  fte_real y[NY], ua[NU], ub[NU], xa[NX], xbh[NX], ya[NY], yb[NY];
  fte_real bad[5];
  int k, i, j, fails = 0, rc;
  feenableexcept(FE_DIVBYZERO | FE_INVALID | FE_OVERFLOW);
  bad[0] = (fte_real)NAN; bad[1] = (fte_real)INFINITY; bad[2] = -(fte_real)INFINITY;
  bad[3] = BIG; bad[4] = -BIG;
  sane(0, y);
  if (fte_@name@_init_from_y(&a, y, NULL) != 0 || fte_@name@_init_from_y(&b, y, NULL) != 0) {
    printf("init refused a sane y\n"); return 1;
  }
  for (k = 0; k < STEPS; ++k) {
    sane(k, y);
    if (k % 3 == 1) {  /* run b sees bad samples first: all entries, then one entry at a time */
      for (j = 0; j < 5; ++j) {
        fte_real yy[NY];
        for (i = 0; i < NY; ++i) yy[i] = bad[j];
        fails += refused(&b, yy);
        for (i = 0; i < NY; ++i) {
          memcpy(yy, y, sizeof yy);
          yy[i] = bad[j];
          fails += refused(&b, yy);
        }
      }
      {
        fte_real yy[NY];  /* init_from_y refuses them too, and leaves the state alone */
        memcpy(&c, &b, sizeof c);
        for (i = 0; i < NY; ++i) yy[i] = bad[k % 5];
        if (fte_@name@_init_from_y(&b, yy, NULL) == 0 || memcmp(&c, &b, sizeof c) != 0) {
          printf("init_from_y accepted a bad y0 or changed the state\n"); fails++;
        }
      }
    }
    if (fte_@name@_step(&a, y, ua, xa, ya) != 0 || fte_@name@_step(&b, y, ub, xbh, yb) != 0) {
      printf("a sane sample was refused at k = %d\n", k); return 1;
    }
    if (memcmp(ua, ub, sizeof ua) || memcmp(xa, xbh, sizeof xa) || memcmp(ya, yb, sizeof ya)
        || memcmp(&a, &b, sizeof a)) {
      printf("no recovery at k = %d\n", k); fails++;
    }
    for (i = 0; i < NU; ++i) if (!(ua[i] == ua[i])) { printf("NaN u\n"); fails++; }
  }
  /* denormal and zero measurements: no trap; accepted (finite outputs) or refused unchanged (3) */
  for (j = 0; j < 2; ++j) {
    memcpy(&c, &a, sizeof c);
    for (i = 0; i < NY; ++i) y[i] = j == 0 ? TINY : (fte_real)0;
    rc = fte_@name@_step(&c, y, ua, xa, ya);
    if (rc == 0) {
      for (i = 0; i < NU; ++i) if (!(ua[i] - ua[i] == 0)) { printf("non-finite u\n"); fails++; }
    } else if (rc != 3 || memcmp(&c, &a, sizeof c) != 0) {
      printf("rc %d on %s\n", rc, j == 0 ? "denormal" : "zero"); fails++;
    }
  }
  /* initial states: a NaN, an infinity or a huge one refused with its code (1, 3), the state untouched */
  for (j = 0; j < 5; ++j) {
    fte_real z[NX], xb[NX];
    memcpy(&c, &a, sizeof c);
    for (i = 0; i < NX; ++i) z[i] = 0;
    z[(3 * j) % NX] = bad[j];
    rc = fte_@name@_init(&c, z);
    if (rc != (j < 3 ? 1 : 3) || memcmp(&c, &a, sizeof c) != 0) { printf("init took bad z0: rc %d\n", rc); fails++; }
    memcpy(xb, fte_@name@_XBAR0, sizeof xb);
    xb[(3 * j) % NX] = bad[j];
    sane(0, y);
    rc = fte_@name@_init_from_y(&c, y, xb);
    if (rc != (j < 3 ? 1 : 3) || memcmp(&c, &a, sizeof c) != 0) { printf("init_from_y took bad xbar0: rc %d\n", rc); fails++; }
  }
  if (fte_@name@_init(&c, 0) != 0) { printf("init refused NULL\n"); fails++; }
  printf(fails ? "FAILED %d\n" : "OK\n", fails);
  return fails != 0;
}
"""


def _sanitizers_work(tmp: Path) -> str | None:
    """None when the compiler builds and runs a program with the sanitizers; else why not."""
    if CC is None:
        return "no C compiler (cc) on PATH"
    src = tmp / "probe.c"
    src.write_text(
        "#define _GNU_SOURCE\n#include <fenv.h>\nint main(void){feenableexcept(FE_INVALID);return 0;}\n"
    )
    r = subprocess.run(
        [CC, *SANITIZE, str(src), "-o", str(tmp / "probe"), "-lm"], capture_output=True, text=True
    )
    if r.returncode != 0:
        return f"the compiler lacks the sanitizers: {r.stderr.strip()[:200]}"
    r = subprocess.run([str(tmp / "probe")], capture_output=True, text=True)
    if r.returncode != 0:
        return f"sanitized programs do not run here: {r.stderr.strip()[:200]}"
    return None


def _harness(plant: str, folder: Path) -> Path:
    d = Design.load(GENERATED / BUILTIN_DIRS[plant] / "design.json")
    y0 = np.asarray(d.C) @ np.asarray(d.xbar0)[: int(d.dims.n)]
    nm = c_name(plant)
    text = HARNESS.replace("@name@", nm).replace("@NAME@", nm.upper())
    text = text.replace("@y0@", ", ".join(repr(float(v)) for v in y0))
    path = folder / "harness.c"
    path.write_text(text)
    return path


def _generate(plant, real, folder):
    generate_c(Design.load(GENERATED / BUILTIN_DIRS[plant] / "design.json"), folder, real=real)
    return sorted(str(p) for p in folder.glob("fte_*.c"))


@pytest.mark.slow
@pytest.mark.parametrize("real", ["double", "float"])
@pytest.mark.parametrize("plant", sorted(BUILTIN_DIRS))
def test_c_recovers_under_traps_and_sanitizers(plant, real, tmp_path):
    why = _sanitizers_work(tmp_path)
    if why:
        pytest.skip(why)
    srcs = _generate(plant, real, tmp_path / "c")
    extra = ["-Wdouble-promotion"] if real == "float" else []
    # the contract's flags (and, in float, no double promotion anywhere in the generated code)
    for src in srcs:
        r = subprocess.run([CC, *CONTRACT, *extra, "-O2", "-c", src, "-o", str(tmp_path / "x.o")],
                           capture_output=True, text=True)  # fmt: skip
        assert r.returncode == 0, r.stderr
    harness = _harness(plant, tmp_path)
    exe = tmp_path / "harness"
    flags = ["-std=c99", *SANITIZE, f"-I{tmp_path / 'c'}"] + (["-DHARNESS_FLOAT"] if real == "float" else [])
    r = subprocess.run(
        [CC, *flags, str(harness), *srcs, "-o", str(exe), "-lm"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    r = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip().endswith("OK"), (r.returncode, r.stdout, r.stderr[-2000:])


@pytest.mark.slow
@pytest.mark.parametrize("real", ["double", "float"])
def test_fast_math_keeps_the_nan_check(real, tmp_path):
    """-ffast-math lets the compiler assume there is no NaN: the check reads the bits, so it stays."""
    if CC is None:
        pytest.skip("no C compiler (cc) on PATH")
    srcs = _generate("manipulator", real, tmp_path / "c")
    harness = _harness("manipulator", tmp_path)
    exe = tmp_path / "harness"
    flags = ["-std=c99", "-O2", "-ffast-math", f"-I{tmp_path / 'c'}"] + (
        ["-DHARNESS_FLOAT"] if real == "float" else []
    )
    r = subprocess.run(
        [CC, *flags, str(harness), *srcs, "-o", str(exe), "-lm"], capture_output=True, text=True
    )
    assert r.returncode == 0, r.stderr
    r = subprocess.run([str(exe)], capture_output=True, text=True, timeout=120)
    assert r.returncode == 0 and r.stdout.strip().endswith("OK"), (r.stdout, r.stderr[-2000:])


def test_no_quotient_by_a_value_that_can_be_zero_in_the_committed_c():
    """The premises' quotients divide by a guarded denominator (1 near 0), not by the measurement itself."""
    src = (GENERATED / "manipulator" / "fte_manipulator_casadi.c").read_text()
    assert "a03=sin(a07);\n  a03=(a03/a07);" in src  # a07 = (|y| < 1e-4 ? 1 : 0) + (|y| >= 1e-4 ? y : 0)
