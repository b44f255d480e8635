"""What one path-step of the vectorised engine costs, and what limits it.

- :func:`op_counts`: the operations of one path-step, counted from the CasADi instruction list of the
  engine's Function plus the random numbers the C loop draws (the central formula of AS 241 for the
  normal, 85 % of the draws; the tail's ``log`` and ``sqrt`` are counted as expected calls);
  ``flops`` counts additions, subtractions, multiplications and divisions (``sq``, ``twice``,
  ``inv`` and ``sqrt``, a vector instruction, as one each); comparisons, selections,
  ``fabs``/``sign``/``neg`` and C library calls are counted apart.
- :func:`peak_flops`: the double-precision peak assumed for this machine, and why.
- :func:`libm_share`: the same compiled engine timed twice in one process, once as is and once with
  the C library calls of the closed loop (``sin``, ``exp``, ...) replaced by a copy of their
  argument: the fraction of the time spent in those scalar calls.
"""

from __future__ import annotations

import os
import re
import time

import casadi as ca
import numpy as np

from fte_casadi.sim._rng import TAIL
from fte_casadi.sim._vector import _CALL, VectorEngine

__all__ = ["peak_flops", "libm_share"]  # public: docs/api.md

_FLOP = {"OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_SQ", "OP_TWICE", "OP_INV", "OP_SQRT"}
#: lane loops that the compiler turns into vector instructions (``vsqrtpd``): not library calls
_VECTORISED_CALLS = {"sqrt"}
_SKIP = {"OP_INPUT", "OP_OUTPUT", "OP_CONST", "OP_ASSIGN"}


def op_counts(F: ca.Function, ld: int) -> dict:
    """Operations of one path-step: the engine Function ``F`` and the driver's random numbers
    (``ld`` uniform inputs)."""
    names = {getattr(ca, k): k for k in dir(ca) if k.startswith("OP_")}
    flops = calls = other = 0
    per_call: dict[str, int] = {}
    for k in range(F.n_instructions()):
        nm = names.get(F.instruction_id(k), "?")
        if nm in _SKIP:
            continue
        if nm in _FLOP:
            flops += 1
        elif nm in _CALL and _CALL[nm] not in _VECTORISED_CALLS:
            calls += 1
            per_call[_CALL[nm]] = per_call.get(_CALL[nm], 0) + 1
        else:
            other += 1
    # the normal: p from the bits (2), q and r (3), two Horner polynomials of degree 7 (28), q num / den (2),
    # times sqrt(dt) (1); per unknown input: the uniform (1), 2u - 1 (2), times the amplitude (1)
    rng_flops = 36 + 4 * ld
    tail = 1.0 - 2.0 * TAIL  # the fraction of uniforms p with |p - 1/2| > TAIL: log and sqrt each
    return {
        "flops": flops + rng_flops,
        "flops_closed_loop": flops,
        "flops_random_numbers": rng_flops,
        "compare_select_other": other,
        "libm_calls": calls,
        "libm_calls_by_function": per_call,
        "random_number_tail_fraction": tail,
        "random_number_libm_calls_expected": 2 * tail,
        "instructions": int(F.n_instructions()),
    }


def _cpuinfo() -> str:
    try:
        with open("/proc/cpuinfo") as fh:
            return fh.read()
    except OSError:
        return ""


def peak_flops() -> dict:
    """The double-precision peak assumed here: cores x clock x doubles per FMA unit x 2 FMA units x
    2 flops per FMA. Doubles per unit: 8 with AVX-512 on a full-width data path, 4 with AVX2 (and
    with AVX-512 on AMD family 25, Zen 3/4, whose units are 256 bits wide), else 2. The clock is the
    largest ``cpu MHz`` of /proc/cpuinfo: the nominal clock in a virtual machine, turbo not counted."""
    info = _cpuinfo()
    mhz = [float(ln.split(":")[1]) for ln in info.splitlines() if ln.startswith("cpu MHz")]
    ghz = (max(mhz) / 1000.0) if mhz else float("nan")
    fam = next((ln.split(":")[1].strip() for ln in info.splitlines() if ln.startswith("cpu family")), "")
    model = next((ln.split(":")[1].strip() for ln in info.splitlines() if ln.startswith("model name")), "")
    amd_half = "AuthenticAMD" in info and fam == "25"
    width = (
        8 if (" avx512f" in info and not amd_half) else 4 if (" avx2" in info or " avx512f" in info) else 2
    )
    cores = os.cpu_count() or 1
    return {
        "cpu": model,
        "cpu_family": fam,
        "cores": cores,
        "ghz": ghz,
        "doubles_per_vector": width,
        "fma_units": 2,
        "flops_per_s": cores * ghz * 1e9 * width * 2 * 2,
    }


def _no_libm(src: str) -> str:
    """The engine's C with every C library call of the closed loop replaced by its (first) argument:
    the same arithmetic otherwise, no scalar calls."""
    calls = "|".join(sorted(set(_CALL.values()) - _VECTORISED_CALLS, key=len, reverse=True))
    return re.sub(rf"\] = (?:{calls})\(", "] = (", src)


def libm_share(prep, paths: int = 256, seed: int = 0, repeats: int = 3) -> dict:
    """Time the engine of ``prep`` (a :class:`fte_casadi.sim._engine.Prepared`) with and without its C
    library calls on ``paths`` paths in one thread, best of ``repeats``: nanoseconds per path-step."""
    F = prep.engine_function
    xs = [r * prep.lay.run_state + j for r in range(3) for j in range(prep.lay.n)]
    bare = VectorEngine(F, xs, name="fte_mc_nolibm", source_filter=_no_libm, par=prep.par)
    S0 = prep.initial_states(np.arange(paths), seed)
    steps = paths * prep.SH.shape[0]

    def best(eng) -> float:
        out = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            eng.run(0, S0, seed, prep.SH, prep.sqdt, prep.damp, 1e300, 0)
            out.append(time.perf_counter() - t0)
        return min(out) / steps * 1e9

    full, without = best(prep.engine), best(bare)
    return {
        "paths": paths,
        "threads": 1,
        "ns_per_path_step": full,
        "ns_per_path_step_without_libm": without,
        "libm_share": max(0.0, 1.0 - without / full),
    }
