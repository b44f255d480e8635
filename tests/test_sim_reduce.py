"""The streamed reduction (issue #11): per-path sums combined exactly, whatever the order of the paths."""

from __future__ import annotations

import numpy as np

from fte_casadi.sim import LossOfEffectiveness, Scenario, Stuck
from fte_casadi.sim.engine import PathLayout
from fte_casadi.sim.reduce import finalize, increments, masks


def _setup():
    sc = Scenario(
        name="r", T=1.0, dt=0.01, faults=(LossOfEffectiveness("fa", 0.4, 0.2, 0.6), Stuck("fs", 0.5, 0.9))
    )
    t = np.arange(101) * 0.01
    mk = masks(t, sc, ["fa", "fs"])
    lay = PathLayout(n=4, nbar=8, lf=2, m=1, p=3, ld=1)
    _, names = increments(lay, mk, np.array([[-1.0, 1.0]]))
    return mk, names


def test_the_document_does_not_depend_on_the_order_of_the_paths():
    """math.fsum: sums of very different magnitudes give the same document in any path order, where a
    plain floating-point sum would not."""
    mk, names = _setup()
    rng = np.random.default_rng(0)
    P = 300
    acc = rng.random((P, len(names))) * 10.0 ** rng.integers(-8, 16, (P, len(names)))
    meta = {"paths": P, "dt": 0.01, "T": 1.0, "seed": 0, "m": 1}
    ref = finalize(acc, names, mk, meta)
    naive_differs = False
    for _ in range(5):
        perm = rng.permutation(P)
        assert finalize(acc[perm], names, mk, meta) == ref
        naive_differs |= bool(np.any(acc[perm].sum(axis=0) != acc.sum(axis=0)))
    assert naive_differs  # the test would catch an order-dependent sum


def test_the_windows_and_saturation_come_from_their_own_sums():
    mk, names = _setup()
    acc = np.zeros((2, len(names)))
    col = {nm: k for k, nm in enumerate(names)}
    acc[:, col["ew0"]], acc[:, col["fw0"]] = [1.0, 3.0], [16.0, 48.0]  # RMS ratio sqrt(4 / 64)
    acc[:, col["aw1"]], acc[:, col["bw1"]] = [2.0, 7.0], [1.0, 0.0]  # deviation ratio sqrt(9 / 1)
    acc[:, col["satw0_0"]] = [40.0, 0.0]  # window 0: 40 samples in [0.2, 0.6) of 2 paths
    doc = finalize(acc, names, mk, {"paths": 2, "dt": 0.01, "T": 1.0, "seed": 0, "m": 1})
    w0, w1 = doc["windows"]
    assert (w0["fault"], w0["start"], w0["stop"]) == ("fa", 0.2, 0.6)
    assert w0["fault_rel_rms_error"] == 0.25 and w0["ftc_deviation_ratio"] is None
    assert w1["ftc_deviation_ratio"] == 3.0 and w1["fault_rel_rms_error"] is None
    assert w0["input_saturation"] == [0.5] and doc["input_saturation"] == [0.0]
