"""Issue #42, item 1: the noise real plants have. Theorem 1's (29) certifies where (45)-(46) do not (a design
certified by it says so, holds P29, and re-certifies on load), and where no design of any structure can exist
(a rule not mean-square stabilisable or detectable with the plant's diffusion) the refusal says it is the plant."""

from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.codegen import CStep, compile_shared, default_sample_time, find_compiler, generate_c
from fte_casadi.design import Design, augment, design, design_summary, recertify
from fte_casadi.design._recertify import certify
from fte_casadi.design.diagnose import decide, limits
from fte_casadi.errors import InfeasibleDesignError
from fte_casadi.step import step_function
from fte_casadi.ts import derive

sys.path.insert(0, str(Path(__file__).resolve().parent))
import plant_ballbeam  # noqa: E402
from tolerances import C_DOUBLE  # noqa: E402


def _aug(noise: float):
    ts = derive(plant_ballbeam.ballbeam(noise), fidelity_samples=200)
    return ts, augment(ts.local_models, ts.C, ts.Df)


@pytest.fixture(scope="module")
def by_theorem_1():
    """The ball and beam at 3 % noise, designed at its defaults (about 15 s)."""
    ts, _ = _aug(0.03)
    return design(ts, sample_time=1e-3)


@pytest.mark.slow
def test_a_design_certified_by_theorem_1_says_so_and_recertifies_on_load(by_theorem_1, tmp_path):
    """The ball and beam at 3 % noise: (46) is infeasible at the defaults, (29) is not; every LMI the certificate
    relies on is re-checked at the returned point, P29 > 0, and the loaded document certifies again."""
    d = by_theorem_1
    assert d.certified and d.checks["certified_by"] == "Theorem 1"
    assert d.P29 is not None and d.checks["P29_min_eig"] > 0
    lam, eps = d.checks["lmi_max_eig"], d.checks["lmi_roundoff"]
    assert all(lam[k] < -eps[k] for k in ("29", "decay", "55", "64"))
    assert lam["46"] > 0  # (46) does not hold: the design exists only by (29)
    assert "certified by Theorem 1's LMI (29)" in design_summary(d)
    assert design_summary(d).splitlines()[0].endswith("CERTIFIED (by Theorem 1's (29))")
    path = tmp_path / "d.json"
    d.save(path)
    loaded = Design.load(path)
    assert np.allclose(loaded.P29, d.P29)
    assert recertify(loaded) == []
    checks = certify(loaded)
    assert (
        checks["certified_by"] == "Theorem 1" and checks["lmi_max_eig"]["29"] < -checks["lmi_roundoff"]["29"]
    )
    # without P29 the document is judged by (45)-(46) alone, and (46) fails: not certified
    doc = loaded.to_dict()
    doc.pop("P29")
    bare = Design.from_dict(doc)
    assert certify(bare)["certified_by"] is None
    assert any("(46)" in why for why in recertify(bare))


@pytest.mark.slow
@pytest.mark.skipif(find_compiler() is None, reason="no C compiler on PATH")
def test_the_c_step_of_a_theorem_1_design_matches_casadi(by_theorem_1, tmp_path):
    """The generated C of the (29)-certified design (P29 is no part of the step) reproduces CasADi's step, at
    states and outputs inside the plant's region (|r| <= 0.3, |phi| <= 0.25)."""
    d = by_theorem_1
    fn = step_function(d, default_sample_time(d))
    generate_c(d, tmp_path, real="double")
    c = CStep(compile_shared(tmp_path, tmp_path / "libstep.so"), d, "double")
    rng = np.random.default_rng(1)
    worst = 0.0
    for _ in range(100):
        z, y = rng.normal(scale=0.05, size=int(d.dims.nbar)), rng.normal(scale=0.05, size=int(d.dims.p))
        zn, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z, y))
        c.init(z)
        rc, uc, xbc, ycc = c.step(y)
        assert rc == 0
        for a, b in ((c.z, zn), (uc, u), (xbc, xb), (ycc, yc)):
            worst = max(worst, float(np.max(np.abs(a - b)) / max(1.0, np.max(np.abs(b)))))
    assert worst <= C_DOUBLE


def test_the_plants_own_limit_brackets_the_diffusion_no_controller_beats():
    """The ball and beam's rule limits (mean-square stabilisability through the torque) at 100 % noise: a bracket
    below 1 (no controller at all makes it mean-square stable with the whole diffusion), and none at 3 %. The
    bracket is checked at its ends by the LMI itself: feasible at the lower end, infeasible at the upper."""
    _, aug = _aug(1.0)
    found = limits(aug)
    assert found and {lim.kind for lim in found} == {"stabilisable"}
    worst = min(found, key=lambda lim: lim.feasible)
    assert 0.3 < worst.feasible < worst.infeasible < 1.0 and worst.infeasible / worst.feasible < 1.2
    assert decide(aug, worst.rule, "stabilisable", worst.feasible, "CLARABEL") is True
    assert decide(aug, worst.rule, "stabilisable", worst.infeasible, "CLARABEL") is False
    _, calm = _aug(0.03)  # 3 % is 1/33 of it: far inside the limit
    assert limits(calm) == []


def test_the_stabilisability_limit_is_that_of_the_exact_second_moments():
    """Independent of any LMI solver: the best state feedback of one rule cannot be mean-square stable above the
    limit. At the bracket's lower end the gain of the LMI (K = Y S^-1) is mean-square stable by the exact test
    (the spectral abscissa of the second moments' operator, Kronecker form)."""
    from fte_casadi.design._augment import time_scale
    from fte_casadi.design.core._sdp import ConicProblem, Layout, Var, affine_lmi

    _, aug = _aug(1.0)
    worst = min(limits(aug), key=lambda lim: lim.feasible)
    i, s, n = worst.rule, worst.feasible, aug.n
    tau = time_scale(aug)
    A, B, W = tau * aug.Abar[i][:n, :n], tau * aug.Bbar[i][:n], s * math.sqrt(tau) * aug.Wbar[i][:n]
    lay = Layout(Var("S", (n, n), True), Var("Y", (B.shape[1], n)))
    res = ConicProblem(lay, [
        affine_lmi("ms", lay, lambda S, Y: np.block([[A @ S + S @ A.T + B @ Y + Y.T @ B.T + 1e-6 * np.eye(n), W @ S],
                                                     [S @ W.T, -S]])),
        affine_lmi("S >= I", lay, lambda S, Y: np.eye(n) - S),
    ]).solve("CLARABEL")  # fmt: skip
    u = lay.unpack(res.v)
    Acl = A + B @ u["Y"] @ np.linalg.inv(u["S"])
    L = np.kron(np.eye(n), Acl) + np.kron(Acl, np.eye(n)) + np.kron(W, W)
    assert np.max(np.linalg.eigvals(L).real) < 0


@pytest.mark.slow
def test_a_refusal_beyond_the_plants_limit_says_it_is_the_plant():
    """At 100 % noise the ball and beam is beyond what any controller can do (above): the refusal names the
    diffusion and says it is the plant, not the method, with the rule's limit."""
    ts, _ = _aug(1.0)
    with pytest.raises(InfeasibleDesignError) as err:
        design(ts, sample_time=1e-3)
    found = err.value.refusal.found
    assert found is not None and getattr(found, "the_plant", False), err.value
    assert "It is the plant, not the method" in str(err.value) and "not mean-square stabilisable" in str(
        err.value
    )
