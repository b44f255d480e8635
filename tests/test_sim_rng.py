"""The counter-based generator's numpy twin (issue #11): uniform and normal, keyed by (seed, path).

That the C draws exactly these numbers is tested in test_sim_vector.py."""

from __future__ import annotations

import math

import numpy as np

from fte_casadi.sim import rng


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


def test_normals_call_the_c_library():
    """Box-Muller through math.log/math.cos (the C library the generated C calls), not numpy's SIMD
    versions, which differ in the last bit for some arguments."""
    keys = rng.path_keys(1, np.arange(30))
    c = np.arange(1, 201, 2, dtype=np.uint64)
    u1, u2 = 1.0 - rng.uniform(keys, c), rng.uniform(keys, c + np.uint64(1))
    want = [[math.sqrt(-2.0 * math.log(a)) * math.cos(6.283185307179586 * b) for a, b in zip(r1, r2)]
            for r1, r2 in zip(u1, u2)]  # fmt: skip
    np.testing.assert_array_equal(rng.normal(keys, c, c + np.uint64(1)), np.array(want))
