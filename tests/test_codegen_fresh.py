"""The committed C of the built-in plants (generated/) is what the generator makes today.

Each ``generated/<plant>/`` holds ``design.json``, the design its code was made from; the code
is regenerated from it into a temporary folder and must be identical byte for byte (the output
is deterministic: no timestamps, constants printed with 17 significant digits). On a failure,
run ``python -c "from fte_casadi.generated import regenerate_builtin; regenerate_builtin('generated')"``
(or ``fte codegen --builtin``) and commit the result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fte_casadi.codegen.generate import BUILTIN_DIRS, generate_c, output_files
from fte_casadi.design import augment
from fte_casadi.design.certify import certificate, failures
from fte_casadi.design.record import Design

GENERATED = Path(__file__).resolve().parents[1] / "generated"


@pytest.mark.parametrize("plant", sorted(BUILTIN_DIRS))
def test_generated_code_is_fresh(plant, tmp_path):
    folder = GENERATED / BUILTIN_DIRS[plant]
    assert (folder / "design.json").is_file(), f"{folder} lacks design.json; regenerate the built-in code"
    design = Design.load(folder / "design.json")
    assert design.plant == plant
    generate_c(design, tmp_path)
    stale = [f for f in output_files(plant) if (folder / f).read_bytes() != (tmp_path / f).read_bytes()]
    assert not stale, (
        f"generated/{BUILTIN_DIRS[plant]}: {stale} differ from a fresh generation; regenerate them"
    )


def test_generation_is_deterministic(tmp_path):
    design = Design.load(GENERATED / "manipulator" / "design.json")
    a, b = tmp_path / "a", tmp_path / "b"
    generate_c(design, a, real="float")
    generate_c(design, b, real="float")
    for f in output_files("manipulator"):
        assert (a / f).read_bytes() == (b / f).read_bytes()


@pytest.mark.parametrize("plant", sorted(BUILTIN_DIRS))
def test_committed_design_is_certified_by_its_own_numbers(plant):
    """The committed design.json holds: every LMI recomputed with numpy from the JSON alone is negative,
    equal to the recorded certificate, and its gains make R_i and A_i + B_i K_j Hurwitz. (A fresh
    solve is not compared with it entry by entry: tests/test_design.py checks that the design is a
    smooth, solver-independent function of the plant instead.)"""
    d = Design.load(GENERATED / BUILTIN_DIRS[plant] / "design.json")
    assert d.certified and d.variant == "conditioned" and d.solves.get("total") == 2
    aug = augment(d.local_models, d.C, d.Df)
    point = dict(X=d.X, K=list(d.K), P=d.P, T=d.T, Pbar=d.Pbar, Q=list(d.Q), N=d.N, theta=d.theta,
                 R=list(d.R), L1=list(d.L1))  # fmt: skip
    checks = certificate(aug, point, d.params.to_dict())
    assert not failures(checks)
    # Recomputed on another machine (other BLAS, other CPU) a largest eigenvalue may differ from the
    # recorded one by the round-off of its matrix, a few eps * dim * ||M||_2 (checks["lmi_roundoff"]).
    # The certificate means something only if its margin is far above that bound, and the two
    # computations must agree within it.
    # (For a slow plant, (55) holds theta ~ 1e10 beside -I: its raw eigenvalue cannot clear eps theta by
    # 1e3, but its balanced form D L D, of the same definiteness, must.)
    for k, v in checks["lmi_max_eig"].items():
        eps, bv, beps = (
            checks["lmi_roundoff"][k],
            checks["lmi_balanced_max_eig"][k],
            checks["lmi_balanced_roundoff"][k],
        )
        assert 0 < eps and (v < -1e3 * eps or bv < -1e3 * beps), (k, v, eps, bv, beps)
        assert v == pytest.approx(d.checks["lmi_max_eig"][k], rel=0, abs=eps), k
    for i in range(d.r):
        R = d.T @ aug.Abar[i] - np.linalg.solve(d.Pbar, d.Q[i]) @ aug.Cbar
        assert np.allclose(R, d.R[i], rtol=1e-9, atol=1e-12)
    assert checks["cond_Pbar"] <= (d.params.kappa or 1e4) and checks["max_abs_L1"] <= 1e3


def test_a_margin_inside_the_roundoff_is_not_a_certificate():
    """failures() refuses a negative largest eigenvalue that is within its matrix's round-off bound."""
    d = Design.load(GENERATED / "manipulator" / "design.json")
    aug = augment(d.local_models, d.C, d.Df)
    point = dict(X=d.X, K=list(d.K), P=d.P, T=d.T, Pbar=d.Pbar, Q=list(d.Q), N=d.N, theta=d.theta,
                 R=list(d.R), L1=list(d.L1))  # fmt: skip
    checks = certificate(aug, point, d.params.to_dict())
    eps, beps = checks["lmi_roundoff"]["46"], checks["lmi_balanced_roundoff"]["46"]
    checks["lmi_max_eig"]["46"] = -0.5 * eps
    checks["lmi_balanced_max_eig"]["46"] = -0.5 * beps
    bad = failures(checks)
    assert len(bad) == 1 and bad[0].startswith("LMI (46)") and "round-off" in bad[0]
    checks["lmi_max_eig"]["46"] = -2 * eps
    assert not failures(checks)
    # a margin beyond the round-off of the balanced form D L D (same definiteness) certifies too
    checks["lmi_max_eig"]["46"] = -0.5 * eps
    checks["lmi_balanced_max_eig"]["46"] = -2 * beps
    assert not failures(checks)
    # without the balanced keys (a document written before them) the raw bound decides alone
    del checks["lmi_balanced_max_eig"], checks["lmi_balanced_roundoff"]
    assert failures(checks)
