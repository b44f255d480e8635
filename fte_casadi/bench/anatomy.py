"""What one path-step of the vectorised engine costs, and what limits it.

- :func:`op_counts`: the operations of one path-step, counted from the CasADi instruction list of the
  engine's Function plus the random numbers the C loop draws (Box-Muller and the uniform inputs);
  ``flops`` counts additions, subtractions, multiplications and divisions (``sq``, ``twice``,
  ``inv`` as one each); comparisons, selections, ``fabs``/``sign``/``neg`` and C library calls are
  counted apart.
- :func:`peak_flops`: the double-precision peak assumed for this machine, and why.
- :func:`libm_share`: the same compiled engine timed twice in one process, once as is and once with
  its C library calls (``sin``, ``cos``, ``log``, ``sqrt`` of the closed loop and of Box-Muller)
  replaced by a copy of their argument: the fraction of the time spent in those scalar calls.
"""

from __future__ import annotations

import os
import re
import time

import casadi as ca
import numpy as np

from ..sim.vector import _CALL, BOX_MULLER, VectorEngine

__all__ = ["op_counts", "peak_flops", "libm_share"]

_FLOP = {"OP_ADD", "OP_SUB", "OP_MUL", "OP_DIV", "OP_SQ", "OP_TWICE", "OP_INV"}
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
        elif nm in _CALL:
            calls += 1
            per_call[_CALL[nm]] = per_call.get(_CALL[nm], 0) + 1
        else:
            other += 1
    # Box-Muller: 1 - u1, -2 log, 2 pi u2, product, times sqrt(dt); per input: 2u, -1, times amplitude
    rng_flops, rng_calls = 5 + 3 * ld, 3
    for c in ("log", "cos", "sqrt"):
        per_call[c] = per_call.get(c, 0) + 1
    return {
        "flops": flops + rng_flops,
        "flops_closed_loop": flops,
        "flops_random_numbers": rng_flops,
        "compare_select_other": other,
        "libm_calls": calls + rng_calls,
        "libm_calls_by_function": per_call,
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
    """The engine's C with every C library call of the closed loop and of Box-Muller replaced by its
    (first) argument: same memory traffic and arithmetic, no scalar calls."""
    calls = "|".join(sorted(set(_CALL.values()), key=len, reverse=True))
    src = re.sub(rf"\] = (?:{calls})\(", "] = (", src)
    return src.replace(f"({BOX_MULLER})", "(u1 - u2)")


def libm_share(prep, paths: int = 256, seed: int = 0, repeats: int = 3) -> dict:
    """Time the engine of ``prep`` (a :class:`fte_casadi.sim.engine.Prepared`) with and without its C
    library calls on ``paths`` paths in one thread, best of ``repeats``: nanoseconds per path-step."""
    F = prep.engine_function
    xs = [r * prep.lay.run_state + j for r in range(3) for j in range(prep.lay.n)]
    bare = VectorEngine(F, xs, name="fte_mc_nolibm", source_filter=_no_libm)
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
