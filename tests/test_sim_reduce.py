"""The streamed reduction: per-path sums combined exactly, whatever the order of the paths."""

from __future__ import annotations

import numpy as np

from fte_casadi.sim import LossOfEffectiveness, Scenario, Stuck
from fte_casadi.sim._engine import PathLayout
from fte_casadi.sim._masks import Allowances, masks
from fte_casadi.sim._reduce import finalize, monitor


def _setup():
    sc = Scenario(
        name="r", T=1.0, dt=0.01, faults=(LossOfEffectiveness("fa", 0.4, 0.2, 0.6), Stuck("fs", 0.5, 0.9))
    )
    t = np.arange(101) * 0.01
    mk = masks(t, sc, ["fa", "fs"], Allowances(0.05, 0.05, 0.1, False, ""))
    lay = PathLayout(n=4, nbar=8, lf=2, m=1, p=3, ld=1)
    C = np.hstack([np.eye(3), np.zeros((3, 1))])
    mo = monitor(lay, mk, C, np.array([[-1.0, 1.0]]), None)
    return t, mk, mo


def _meta(P):
    return {"paths": P, "dt": 0.01, "T": 1.0, "seed": 0, "m": 1, "thresholds": [1.0, 1.0],
            "detection": [{"fault": "fa"}, {"fault": "fs"}]}  # fmt: skip


def test_the_document_does_not_depend_on_the_order_of_the_paths():
    """math.fsum: sums of very different magnitudes give the same document in any path order, where a
    plain floating-point sum would not."""
    t, mk, mo = _setup()
    rng = np.random.default_rng(0)
    P = 300
    acc = rng.random((P, len(mo.names))) * 10.0 ** rng.integers(-8, 16, (P, len(mo.names)))
    mon = rng.random((P, mo.nmon))
    pm = rng.random((len(t), len(mo.pm_names)))
    ref = finalize(acc, mon, pm, t, mo, mk, _meta(P))
    naive_differs = False
    for _ in range(5):
        perm = rng.permutation(P)
        assert finalize(acc[perm], mon[perm], pm, t, mo, mk, _meta(P)) == ref
        naive_differs |= bool(np.any(acc[perm].sum(axis=0) != acc.sum(axis=0)))
    assert naive_differs  # the test would catch an order-dependent sum


def test_the_windows_and_saturation_come_from_their_own_sums():
    t, mk, mo = _setup()
    acc = np.zeros((2, len(mo.names)))
    col = {nm: k for k, nm in enumerate(mo.names)}
    acc[:, col["ew0"]], acc[:, col["fw0"]] = [1.0, 3.0], [16.0, 48.0]  # RMS ratio sqrt(4 / 64)
    acc[:, col["ew1"]], acc[:, col["fw1"]] = [1.0, 3.0], [16.0, 48.0]
    acc[:, col["at1_0"]], acc[:, col["bt1_0"]] = [2.0, 7.0], [1.0, 0.0]  # true ratio of output 0: sqrt(9 / 1)
    acc[:, col["satw0_0"]] = [40.0, 0.0]  # window 0: 40 samples in [0.2, 0.6) of 2 paths
    mon = np.tile(mo.mon0(), (2, 1))
    pm = np.zeros((len(t), len(mo.pm_names)))
    doc = finalize(acc, mon, pm, t, mo, mk, _meta(2))
    w0, w1 = doc["windows"]
    assert (w0["fault"], w0["start"], w0["stop"]) == ("fa", 0.2, 0.6)
    assert w0["fault_rel_rms_error"] == 0.25 and w0["ftc_true_ratio"] is None
    assert w1["ftc_true_ratio_per_output"][0] == 3.0 and w1["ftc_true_ratio"] == 3.0
    assert w0["input_saturation"] == [0.5] and doc["input_saturation"] == [0.0]
    assert w0["missed_detections"] == 2 and w0["detection_delay"] is None  # no path reached the threshold
