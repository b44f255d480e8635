"""The paper variant: Section 4.3 exactly as printed (with the corrections of docs/method.md), one solve per step.

Step 3 is the feasibility problem (45) for ``X > 0`` and one ``Y_j`` per rule, with no objective;
step 5 is ``min theta`` subject to (46) for every ``(i, j)``, (55), (64) and ``Pbar > 0`` with ``Q_i``
and ``N`` free. Strict inequalities become ``<= -1e-7 I``. The solver's point is taken as it is
(no centring: this variant shows what the printed problem gives), and only ever reported with
its certificate recomputed at that point. Because ``Cbar J1 = 0``, (20) forces
``J1^T Pbar J1 = 0`` and ``min theta`` drives Pbar towards singular: expect a huge cond(Pbar)
and huge gains, or an infeasibility report (docs/method.md, "Equality (20) is never exactly feasible").
"""

from __future__ import annotations

import numpy as np

from ...errors import InfeasibleDesignError
from .._augment import Augmented
from ._conditioned import Step3, Step5
from ._lmis import PAPER3, PAPER5, STRICT, Posed, posed
from ._sdp import SOLVED, ConicProblem, Layout, Var, affine_lmi

__all__ = ["step3", "step5", "STRICT"]


def step3(aug: Augmented, params: dict, solver: str) -> tuple[Step3, list[np.ndarray]]:
    """Feasibility of (45) for X and Y_j (one per rule); returns the step and the gains K_j."""
    n, m, r = aug.n, aug.m, aug.r
    sg, g, g1 = params["sigma"], params["gamma"], params["gamma1"]
    layout = Layout(Var("X", (n, n), True), *[Var(f"Y{j}", (m, n)) for j in range(r)])
    lmis = posed(PAPER3, Posed(aug, params, layout))  # (45) for every rule i and gain j
    lmis.append(affine_lmi("X > 0", layout, lambda **u: STRICT * np.eye(n) - u["X"]))
    prob = ConicProblem(layout, lmis)
    res = prob.solve(solver)
    if res.v is None or res.status not in SOLVED:
        kind = "infeasible" if res.infeasible else f"not solved ({res.status})"
        raise InfeasibleDesignError(
            f"LMI (45) as printed is {kind} for gamma = {g:g}, gamma1 = {g1:g}, sigma = {sg:g} ({solver}: {res.status}); "
            "raise gamma or lower sigma, or use variant='conditioned', which also names the feasible bounds"
        )
    u = layout.unpack(res.v)
    X = u["X"]
    K = [u[f"Y{j}"] @ np.linalg.inv(X) for j in range(r)]
    notes = [
        f"step 3 (paper): feasibility of (45) with one Y_j per rule, no objective; 1 solve ({res.status})"
    ]
    return Step3(X, K[0], res.status, prob.solves, prob.seconds, notes), K


def step5(aug: Augmented, params: dict, X, K: list, T, solver: str) -> Step5:
    """``min theta`` s.t. (46) for every (i, j), (55), (64), Pbar > 0 (Q_i, N free)."""
    p, nbar, lf, r = aug.p, aug.nbar, aug.ns, aug.r  # ns = lf (+ Remark 5's directions)
    layout = Layout(Var("Pbar", (nbar, nbar), True), *[Var(f"Q{i}", (nbar, p)) for i in range(r)],
                    Var("N", (lf, p)), Var("theta", ()))  # fmt: skip
    lmis = posed(PAPER5, Posed(aug, params, layout, K=K, T=T, X=X))  # (46) for every (i, j), (55), (64)
    lmis.append(affine_lmi("Pbar > 0", layout, lambda **u: STRICT * np.eye(nbar) - u["Pbar"]))
    c = np.zeros(layout.size)
    c[layout.index("theta")] = 1.0
    prob = ConicProblem(layout, lmis, c)
    res = prob.solve(solver)
    if res.v is None or res.status not in SOLVED:
        kind = "infeasible" if res.infeasible else f"not solved ({res.status})"
        raise InfeasibleDesignError(
            f"LMI (46) with (55), (64) as printed is {kind} ({solver}: {res.status}); the paper variant is "
            "ill-conditioned (equality (20) cannot hold with Pbar > 0): use variant='conditioned'"
        )
    u = layout.unpack(res.v)
    notes = [
        f"step 5 (paper): min theta s.t. (46), (55), (64), Pbar > 0 with Q_i, N free; 1 solve ({res.status})"
    ]
    return Step5(u["Pbar"], [u[f"Q{i}"] for i in range(r)], u["N"], float(u["theta"]), 0.0, res.status,
                 prob.solves, prob.seconds, {"alpha": 0.0, "why": "the paper variant imposes no decay rate"}, notes)  # fmt: skip
