"""The Monte Carlo's random numbers: a counter-based SplitMix64, in C and as an exact numpy twin.

Path ``i`` of a run with seed ``s`` has the key ``mix(mix(s) ^ (i * GOLDEN))``; its ``c``-th 64-bit
number is ``mix(key + c * GOLDEN)`` (SplitMix64 with random access). A number depends only on
``(seed, path, counter)``, never on how paths are grouped into chunks, threads or workers, and the
generated C draws it inside its loop, so no random array is ever held for all paths.

Counters of sample ``k`` (``NSLOT = 2 + ld`` per sample): ``k NSLOT + 1`` and ``+ 2`` give two
uniforms for one Box-Muller normal (``dW = sqrt(dt) N``), ``+ 3 ..`` the unknown inputs (uniform).
The initial-state noise uses the key ``mix(key ^ X0_SALT)`` and counters ``2 j + 1, 2 j + 2``
for state j. Uniforms are ``(r >> 11) 2^-53``; Box-Muller takes ``u1 = 1 - uniform`` (never 0).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["C_SOURCE", "path_keys", "uniform", "normal", "step_numbers", "x0_normals", "GOLDEN", "X0_SALT"]

GOLDEN = 0x9E3779B97F4A7C15
X0_SALT = 0xD1B54A32D192ED03
_M1, _M2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB

#: the C twin (``fte_mix``, ``fte_key``, ``fte_u01``); the emitter pastes it into the engine's source
C_SOURCE = f"""
static inline uint64_t fte_mix(uint64_t z) {{
  z = (z ^ (z >> 30)) * UINT64_C({_M1:#x});
  z = (z ^ (z >> 27)) * UINT64_C({_M2:#x});
  return z ^ (z >> 31);
}}
static inline uint64_t fte_key(uint64_t seed, uint64_t path) {{
  return fte_mix(fte_mix(seed) ^ (path * UINT64_C({GOLDEN:#x})));
}}
static inline double fte_u01(uint64_t key, uint64_t c) {{
  return (double)(fte_mix(key + c * UINT64_C({GOLDEN:#x})) >> 11) * 0x1.0p-53;
}}
"""


def _mix(z: np.ndarray) -> np.ndarray:
    z = z.astype(np.uint64)
    with np.errstate(over="ignore"):
        z = (z ^ (z >> np.uint64(30))) * np.uint64(_M1)
        z = (z ^ (z >> np.uint64(27))) * np.uint64(_M2)
    return z ^ (z >> np.uint64(31))


def path_keys(seed: int, paths) -> np.ndarray:
    """The keys of ``paths`` (integers) for ``seed``."""
    p = np.asarray(paths, dtype=np.uint64)
    with np.errstate(over="ignore"):
        return _mix(_mix(np.full(p.shape, seed, dtype=np.uint64)) ^ (p * np.uint64(GOLDEN)))


def uniform(keys: np.ndarray, counters) -> np.ndarray:
    """Uniforms in [0, 1): ``keys`` (paths,) against ``counters`` (...,) -> (paths, ...)."""
    c = np.asarray(counters, dtype=np.uint64)
    with np.errstate(over="ignore"):
        r = _mix(keys.reshape((-1,) + (1,) * c.ndim) + c * np.uint64(GOLDEN))
    return (r >> np.uint64(11)).astype(np.float64) * 2.0**-53


def _libm(fn, x: np.ndarray) -> np.ndarray:
    """``fn`` (``math.log``, ``math.cos``: the C library's, as the generated C calls it) elementwise.

    numpy's own ``log`` takes SIMD code paths that differ from the C library in the last bit for
    some arguments (measured: 1 in 300), so the twin calls the C library itself."""
    flat = np.fromiter(map(fn, x.ravel().tolist()), dtype=np.float64, count=x.size)
    return flat.reshape(x.shape)


def normal(keys: np.ndarray, c1, c2) -> np.ndarray:
    """Box-Muller normals from the uniforms of counters ``c1`` and ``c2`` (bit for bit the C's)."""
    u1 = 1.0 - uniform(keys, c1)
    u2 = uniform(keys, c2)
    return np.sqrt(-2.0 * _libm(math.log, u1)) * _libm(math.cos, 6.283185307179586 * u2)


def step_numbers(seed: int, paths, k0: int, steps: int, ld: int) -> tuple[np.ndarray, np.ndarray]:
    """Standard normals (paths, steps) for dW and uniforms in [-1, 1) (paths, steps, ld) for d,
    of samples ``k0 .. k0 + steps - 1`` — exactly what the generated C draws."""
    keys = path_keys(seed, paths)
    nslot = 2 + ld
    k = np.arange(k0, k0 + steps, dtype=np.uint64) * np.uint64(nslot)
    n = normal(keys, k + np.uint64(1), k + np.uint64(2))
    d = np.stack([2.0 * uniform(keys, k + np.uint64(3 + j)) - 1.0 for j in range(ld)], axis=-1) if ld else (
        np.zeros((len(keys), steps, 0)))  # fmt: skip
    return n, d


def x0_normals(seed: int, paths, n: int) -> np.ndarray:
    """Standard normals (paths, n) of the initial-state noise."""
    keys = path_keys(seed, paths)
    with np.errstate(over="ignore"):
        xk = _mix(keys ^ np.uint64(X0_SALT))
    j = np.arange(n, dtype=np.uint64)
    return normal(xk, 2 * j + np.uint64(1), 2 * j + np.uint64(2))
