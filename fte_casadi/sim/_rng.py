"""The Monte Carlo's random numbers: a counter-based SplitMix64, in C and as an exact numpy twin.

Path ``i`` of a run with seed ``s`` has the key ``mix(mix(s) ^ (i * GOLDEN))``; its ``c``-th 64-bit
number is ``mix(key + c * GOLDEN)`` (SplitMix64 with random access). A number depends only on
``(seed, path, counter)``, never on how paths are grouped into chunks, threads or workers, and the
generated C draws it inside its loop, so no random array is ever held for all paths.

Uniforms in [0, 1) are ``(r >> 11) 2^-53``. A standard normal is the inverse normal distribution
function of an open uniform ``p = ((r >> 12) + 1/2) 2^-52`` (never 0 or 1), by Wichura's algorithm
AS 241 (PPND16, relative accuracy about 1e-16; R's ``qnorm``): a rational function of ``p`` for
``|p - 1/2| <= 0.425`` (85 % of the draws, no library call, computed for 8 paths at once), else a
rational function of ``sqrt(-log(min(p, 1 - p)))``. Unlike Box-Muller it needs one uniform per
normal and calls ``log`` and ``sqrt`` for 15 % of the draws only.

Counters of sample ``k`` (``NSLOT = 1 + ld + nv`` per sample, ``nv`` the outputs with measurement noise, 0
without): ``k NSLOT + 1`` gives the normal of ``dW = sqrt(dt) N``, ``k NSLOT + 2 ..`` the unknown inputs
(uniform in [-1, 1)), ``k NSLOT + 2 + ld + j`` the normal of output j's measurement noise
(:func:`noise_normals`; ``_vector.py`` draws the same in its C). The initial-state noise uses the key
``mix(key ^ X0_SALT)`` and counter ``j + 1`` for state j.

The numpy twin does the same IEEE operations in the same order and calls the C library's ``log``
(through :mod:`math`; numpy's own SIMD ``log`` differs in the last bit for some arguments), so it
returns the C's numbers bit for bit.
"""

from __future__ import annotations

import math

import numpy as np

__all__ = ["uniform", "normal"]  # public: docs/api.md

GOLDEN = 0x9E3779B97F4A7C15
X0_SALT = 0xD1B54A32D192ED03
_M1, _M2 = 0xBF58476D1CE4E5B9, 0x94D049BB133111EB
#: |p - 1/2| beyond which AS 241 takes its tail formulas (15 % of the draws)
TAIL = 0.425

# AS 241 (Wichura 1988, Appl. Statist. 37, 477-484), highest power first; each denominator ends in 1
_A = (2509.0809287301226727, 33430.575583588128105, 67265.770927008700853, 45921.953931549871457,
      13731.693765509461125, 1971.5909503065514427, 133.14166789178437745, 3.387132872796366608)  # fmt: skip
_B = (5226.495278852545925, 28729.085735721942674, 39307.89580009271061, 21213.794301586595867,
      5394.1960214247511077, 687.1870074920579083, 42.313330701600911252, 1.0)  # fmt: skip
_C = (7.7454501427834140764e-4, 0.0227238449892691845833, 0.24178072517745061177, 1.27045825245236838258,
      3.64784832476320460504, 5.7694972214606914055, 4.6303378461565452959, 1.42343711074968357734)  # fmt: skip
_D = (1.05075007164441684324e-9, 5.475938084995344946e-4, 0.0151986665636164571966, 0.14810397642748007459,
      0.68976733498510000455, 1.6763848301838038494, 2.05319162663775882187, 1.0)  # fmt: skip
_E = (2.01033439929228813265e-7, 2.71155556874348757815e-5, 0.0012426609473880784386, 0.026532189526576123093,
      0.29656057182850489123, 1.7848265399172913358, 5.4637849111641143699, 6.6579046435011037772)  # fmt: skip
_F = (2.04426310338993978564e-15, 1.4215117583164458887e-7, 1.8463183175100546818e-5, 7.868691311456132591e-4,
      0.0148753612908506148525, 0.13692988092273580531, 0.59983220655588793769, 1.0)  # fmt: skip


def _c_horner(coef, x: str, lit) -> str:
    """``(((c0 x + c1) x + c2) ...)`` as C, constants through ``lit`` (a broadcast for vectors)."""
    e = f"{lit(coef[0])} * {x}"
    for c in coef[1:-1]:
        e = f"({e} + {lit(c)}) * {x}"
    return f"({e} + {lit(coef[-1])})"


def _np_horner(coef, x: np.ndarray) -> np.ndarray:
    e = coef[0] * x
    for c in coef[1:-1]:
        e = (e + c) * x
    return e + coef[-1]


def central_c(q: str, r: str, lit=repr) -> str:
    """The central formula of AS 241 as a C expression of ``q = p - 1/2`` and ``r = 0.180625 - q q``
    (C names, defined by the caller), constants written by ``lit``."""
    return f"{q} * {_c_horner(_A, r, lit)} / {_c_horner(_B, r, lit)}"


#: the C twin (``fte_mix``, ``fte_key``, ``fte_u01``, ``fte_p01``, ``fte_ndtri_tail``); the emitter pastes
#: it into the engine's source and writes the central formula over lane vectors with :func:`central_c`
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
static inline double fte_p01(uint64_t key, uint64_t c) {{
  return ((double)(fte_mix(key + c * UINT64_C({GOLDEN:#x})) >> 12) + 0.5) * 0x1.0p-52;
}}
static double fte_ndtri_tail(double p) {{  /* AS 241 for |p - 1/2| > {TAIL} */
  double q = p - 0.5, r = sqrt(-log(q < 0.0 ? p : 1.0 - p)), v;
  if (r <= 5.0) {{
    r = r - 1.6;
    v = {_c_horner(_C, "r", repr)} / {_c_horner(_D, "r", repr)};
  }} else {{
    r = r - 5.0;
    v = {_c_horner(_E, "r", repr)} / {_c_horner(_F, "r", repr)};
  }}
  return q < 0.0 ? -v : v;
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


def _bits(keys: np.ndarray, counters) -> np.ndarray:
    c = np.asarray(counters, dtype=np.uint64)
    with np.errstate(over="ignore"):
        return _mix(keys.reshape((-1,) + (1,) * c.ndim) + c * np.uint64(GOLDEN))


def uniform(keys: np.ndarray, counters) -> np.ndarray:
    """Uniforms in [0, 1): ``keys`` (paths,) against ``counters`` (...,) -> (paths, ...)."""
    return (_bits(keys, counters) >> np.uint64(11)).astype(np.float64) * 2.0**-53


def open_uniform(keys: np.ndarray, counters) -> np.ndarray:
    """Uniforms in (0, 1), symmetric about 1/2: ``((r >> 12) + 1/2) 2^-52``."""
    return ((_bits(keys, counters) >> np.uint64(12)).astype(np.float64) + 0.5) * 2.0**-52


def _libm(fn, x: np.ndarray) -> np.ndarray:
    """``fn`` (``math.log``: the C library's, as the generated C calls it) elementwise."""
    return np.fromiter(map(fn, x.ravel().tolist()), dtype=np.float64, count=x.size).reshape(x.shape)


def ndtri(p: np.ndarray) -> np.ndarray:
    """The inverse standard normal distribution function by AS 241, as the C computes it."""
    p = np.asarray(p, dtype=np.float64)
    q = p - 0.5
    q_r = 0.180625 - q * q
    z = q * _np_horner(_A, q_r) / _np_horner(_B, q_r)
    tail = ~(np.abs(q) <= TAIL)
    if tail.any():
        pt, qt = p[tail], q[tail]
        r = np.sqrt(-_libm(math.log, np.where(qt < 0.0, pt, 1.0 - pt)))
        lo = r <= 5.0
        v = np.empty_like(r)
        r1, r2 = r[lo] - 1.6, r[~lo] - 5.0
        v[lo] = _np_horner(_C, r1) / _np_horner(_D, r1)
        v[~lo] = _np_horner(_E, r2) / _np_horner(_F, r2)
        z[tail] = np.where(qt < 0.0, -v, v)
    return z


def normal(keys: np.ndarray, counters) -> np.ndarray:
    """Standard normals of ``counters`` (bit for bit the C's)."""
    return ndtri(open_uniform(keys, counters))


def step_numbers(seed: int, paths, k0: int, steps: int, ld: int) -> tuple[np.ndarray, np.ndarray]:
    """Standard normals (paths, steps) for dW and uniforms in [-1, 1) (paths, steps, ld) for d,
    of samples ``k0 .. k0 + steps - 1`` — exactly what the generated C draws."""
    keys = path_keys(seed, paths)
    nslot = 1 + ld
    k = np.arange(k0, k0 + steps, dtype=np.uint64) * np.uint64(nslot)
    n = normal(keys, k + np.uint64(1))
    d = np.stack([2.0 * uniform(keys, k + np.uint64(2 + j)) - 1.0 for j in range(ld)], axis=-1) if ld else (
        np.zeros((len(keys), steps, 0)))  # fmt: skip
    return n, d


def noise_normals(seed: int, paths, k: int, ld: int, nv: int) -> np.ndarray:
    """Standard normals (paths, nv) of the measurement noise of sample ``k`` — what the generated C draws."""
    keys = path_keys(seed, paths)
    base = np.uint64(k) * np.uint64(1 + ld + nv) + np.uint64(2 + ld)
    return np.column_stack(
        [normal(keys, np.array([base + np.uint64(j)], dtype=np.uint64))[:, 0] for j in range(nv)]
    )


def x0_normals(seed: int, paths, n: int) -> np.ndarray:
    """Standard normals (paths, n) of the initial-state noise."""
    keys = path_keys(seed, paths)
    with np.errstate(over="ignore"):
        xk = _mix(keys ^ np.uint64(X0_SALT))
    return normal(xk, np.arange(1, n + 1, dtype=np.uint64))
