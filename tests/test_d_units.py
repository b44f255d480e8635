"""The unit of an unknown input does not change the design (the issue: a flexible joint's load torque in N m
was given gamma 120, the same input in rad/s^2 gamma 1, and the two designs differed by 7.8 relative).

The generic gamma and gamma1 are taken in the unknown inputs' own size ``sd``
(:func:`~fte_casadi.design._augment.unknown_input_size`), which follows d's unit exactly: with ``d' = c d``,
``Bd' = Bd / c`` and ``sd' = sd / c``. What follows (derived, not fitted): (45)'s d block
``[.., Bd; Bd^T, (gamma1^2 - gamma^2) I]`` at ``(gamma / c, gamma1 / c)`` is congruent to the one at
``(gamma, gamma1)`` by ``diag(I, I, I, c I)``, with step 3's margin on it, and its other blocks do not hold d:
the same X and K. H and T depend on d only through the range of ``C Bd`` (unchanged), d enters (46) only in
its decoupled ``-gamma1^2 I`` block (its d2 block is Theorem 5's other input) and (55), (64) not at all: the
same Pbar, Q, L_i1, N, Kf and decay rate. So only gamma and gamma1 scale, by ``1 / c``; every gain is the
same. The parameter search rounds its gammas in units of ``sy sd``, so its choice scales with them.
"""

from __future__ import annotations

import casadi as ca
import numpy as np
import pytest

from fte_casadi import PlantBuilder
from fte_casadi.design import design
from fte_casadi.design._augment import augment, unknown_input_size
from fte_casadi.ts import derive

I_L, J_M, K_S, MGL, B_M = 0.031, 0.004, 7.13, 0.8, 0.007  # kg m^2, kg m^2, N m/rad, N m, N m s
C_UNIT = 1.0 / I_L  # d in rad/s^2 is c = 1 / I_l times d in N m: not a power of two


def joint(d_unit: str):
    """A flexible joint: link (q1, w1), motor (q2, w2), a spring between; the load torque d acts on the link,
    in N m (``d / I_l``) or as the acceleration it gives (rad/s^2); the motor torque has an actuator fault,
    the motor speed sensor a bias; no design defaults."""
    b = PlantBuilder(f"joint_{d_unit}")
    q1, w1, q2, w2 = b.states("q1", "w1", "q2", "w2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    (fs,) = b.faults("fs", kind="sensor")
    load = d / I_L if d_unit == "N m" else d
    b.drift([
        w1,
        (-MGL * ca.sin(q1) - K_S * (q1 - q2)) / I_L + load,
        w2,
        (K_S * (q1 - q2) - B_M * w2 + u + fa) / J_M,
    ])  # fmt: skip
    b.diffusion([0.0, 0.01 * w1, 0.0, 0.0])
    b.outputs([q1, q2, w1, w2 + fs])
    b.region(q1=(-1.5, 1.5), w1=(-5.0, 5.0), q2=(-1.5, 1.5), w2=(-5.0, 5.0))
    return b.build()


@pytest.fixture(scope="module")
def plants():
    return [derive(joint(u), fidelity_samples=300) for u in ("N m", "rad/s^2")]


def test_the_unknown_inputs_size_follows_its_unit(plants):
    nm, rad = (unknown_input_size(augment(ts.local_models, ts.C, ts.Df)) for ts in plants)
    assert nm == pytest.approx(C_UNIT * rad, rel=1e-12)


def test_d_in_two_units_gives_the_same_design(plants):
    """Both certified at the defaults (the search lowers sigma alike); gamma, gamma1 scale by 1/c; K, L_i1, H,
    Kf, N, Pbar, the decay rate and the largest sample time agree. The tolerance: the two designs solve the
    same centred problem from two floating-point data sets equal up to round-off (Bd / c), through a centring
    to a gap of 0.5 with cond(Pbar) <= 1e4; 1e-6 relative is far above what that round-off can reach (measured:
    4e-12 for Pbar and N, 3e-14 for K and L_i1)."""
    a, b = (design(ts) for ts in plants)
    assert a.certified and b.certified
    assert a.params.sigma == b.params.sigma
    assert a.params.gamma == pytest.approx(C_UNIT * b.params.gamma, rel=1e-9)
    assert a.params.gamma1 == pytest.approx(C_UNIT * b.params.gamma1, rel=1e-9)
    for k in ("K", "L1"):
        for Ma, Mb in zip(getattr(a, k), getattr(b, k)):
            np.testing.assert_allclose(
                np.asarray(Ma), np.asarray(Mb), rtol=1e-6, atol=1e-6 * np.abs(Ma).max()
            )
    for k in ("H", "Kf", "N", "Pbar"):
        Ma, Mb = np.asarray(getattr(a, k)), np.asarray(getattr(b, k))
        np.testing.assert_allclose(Ma, Mb, rtol=1e-6, atol=1e-6 * np.abs(Ma).max())
    assert a.observer.alpha == pytest.approx(b.observer.alpha, rel=1e-6)
    assert a.checks["ts_max"] == pytest.approx(b.checks["ts_max"], rel=1e-6)


@pytest.mark.slow
def test_the_gammas_tried_scale_with_d(plants):
    """The gammas the tool tries above the frontier of (45) (``explore``, as the parameter search) are rounded
    in units of ``sy sd``: with d in N m they are c times those with d in rad/s^2, and so is the frontier."""
    from fte_casadi.design import explore

    (pa,), _ = explore(plants[0], gamma1=1e-3 * C_UNIT, sigmas=[0.2])
    (pb,), _ = explore(plants[1], gamma1=1e-3, sigmas=[0.2])
    assert pa.certified and pb.certified
    assert pa.gamma_min == pytest.approx(C_UNIT * pb.gamma_min, rel=1e-6)
    assert pa.gamma_tried == pytest.approx(C_UNIT * pb.gamma_tried, rel=1e-9)
    assert pa.alpha == pytest.approx(pb.alpha, rel=1e-6)
