"""The counter-based generator's numpy twin (issue #11): uniform and normal, keyed by (seed, path).

That the C draws exactly these numbers is tested in test_sim_vector.py."""

from __future__ import annotations

import math

import numpy as np

from fte_casadi.sim import _rng as rng


def test_uniforms_and_normals_have_their_moments():
    keys = rng.path_keys(3, np.arange(200))
    u = rng.uniform(keys, np.arange(500, dtype=np.uint64))
    assert u.shape == (200, 500) and u.min() >= 0.0 and u.max() < 1.0
    se = math.sqrt(1 / 12 / u.size)
    assert abs(u.mean() - 0.5) < 4 * se
    n, d = rng.step_numbers(3, np.arange(200), 0, 500, 2)
    assert n.shape == (200, 500) and d.shape == (200, 500, 2)
    assert abs(n.mean()) < 4 / math.sqrt(n.size) and abs(n.var() - 1) < 4 * math.sqrt(2 / n.size)
    assert d.min() >= -1 and d.max() < 1 and abs(d.mean()) < 4 * math.sqrt(1 / 3 / d.size)
    # neighbouring samples, inputs and paths are uncorrelated
    assert abs(np.corrcoef(n[:, :-1].ravel(), n[:, 1:].ravel())[0, 1]) < 4 / math.sqrt(n.size)
    assert abs(np.corrcoef(d[..., 0].ravel(), d[..., 1].ravel())[0, 1]) < 4 / math.sqrt(n.size)
    assert abs(np.corrcoef(n[:-1].ravel(), n[1:].ravel())[0, 1]) < 4 / math.sqrt(n.size)


def test_numbers_depend_on_seed_path_and_sample_only():
    n_all, _ = rng.step_numbers(9, np.arange(10), 0, 40, 1)
    n_part, _ = rng.step_numbers(9, [7, 3], 25, 15, 1)  # other paths, a later block
    np.testing.assert_array_equal(n_part, n_all[[7, 3], 25:])
    n_seed, _ = rng.step_numbers(10, np.arange(10), 0, 40, 1)
    assert not np.any(n_seed == n_all)
    # the initial-state noise is its own stream: not the first step numbers of the path
    x0 = rng.x0_normals(9, np.arange(10), 4)
    assert x0.shape == (10, 4) and not np.any(np.isin(x0, n_all))


def test_normals_are_the_inverse_normal_distribution_function():
    """AS 241 against scipy's ndtri: the same numbers to ~1e-16 relative over the centre and both tails
    (down to p = 2^-53), and odd about p = 1/2 bit for bit."""
    from scipy.special import ndtri

    p = np.concatenate([np.linspace(1e-6, 1 - 1e-6, 20001), [2.0**-53, 1e-12, 1e-9, 0.075, 0.0749999, 0.925,
                        0.5, 1 - 1e-9, 1 - 2.0**-53]])  # fmt: skip
    z = rng.ndtri(p)
    np.testing.assert_allclose(z, ndtri(p), rtol=1e-15, atol=1e-15)
    hi = p >= 0.5  # 1 - p is exact there (Sterbenz)
    np.testing.assert_array_equal(rng.ndtri(1.0 - p[hi]), -z[hi])
    assert z[np.argmin(p)] < -8.2 and rng.ndtri(np.array([0.5]))[0] == 0.0
    keys = rng.path_keys(1, np.arange(30))
    u = rng.open_uniform(keys, np.arange(1, 301, dtype=np.uint64))
    assert u.min() > 0 and u.max() < 1  # never 0 or 1: the normal is always finite


def test_tail_calls_the_c_library():
    """The tail formula takes log through math.log (the C library the generated C calls), not numpy's
    SIMD log, which differs in the last bit for some arguments."""
    p = np.array([0.01, 0.03, 0.95, 0.99, 1e-5])
    q = p - 0.5
    r = [math.sqrt(-math.log(a if b < 0 else 1.0 - a)) for a, b in zip(p, q)]
    assert all(v <= 5.0 for v in r)
    num = [((((((((rng._C[0] * (x - 1.6) + rng._C[1]) * (x - 1.6) + rng._C[2]) * (x - 1.6) + rng._C[3])
            * (x - 1.6) + rng._C[4]) * (x - 1.6) + rng._C[5]) * (x - 1.6) + rng._C[6]) * (x - 1.6)) + rng._C[7])
           for x in r]  # fmt: skip
    den = [((((((((rng._D[0] * (x - 1.6) + rng._D[1]) * (x - 1.6) + rng._D[2]) * (x - 1.6) + rng._D[3])
            * (x - 1.6) + rng._D[4]) * (x - 1.6) + rng._D[5]) * (x - 1.6) + rng._D[6]) * (x - 1.6)) + rng._D[7])
           for x in r]  # fmt: skip
    want = [(-a / b if c < 0 else a / b) for a, b, c in zip(num, den, q)]
    np.testing.assert_array_equal(rng.ndtri(p), np.array(want))
