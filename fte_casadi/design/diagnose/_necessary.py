"""What no observer can do: the plant's own limit on the diffusion, a necessary condition for ANY design.

For one rule's local model ``dx = (A x + B u) dt + W x dw``, ``y = C x`` (faults and unknown inputs zero), let a
linear controller ``dz = (Ac z + Bc y) dt``, ``u = Cc z + Dc y`` (the observer (10) with the control law (22) is
one: the sliding term and f'' are inputs, and d is decoupled) make the closed loop ``xi = [x; z]`` mean-square
stable. Its Lyapunov operator is resolvent positive, so there are ``S > 0`` and ``P > 0`` with
``Acl S + S Acl^T + Wcl S Wcl^T < 0`` and ``Acl^T P + P Acl + Wcl^T P Wcl < 0`` (``Wcl = diag(W, 0)``). Their
x blocks give

- ``A S11 + S11 A^T + B Y + Y^T B^T + W S11 W^T < 0`` with ``Y = Dc C S11 + Cc S21``: ``(A + B K, W)`` is
  mean-square stable for ``K = Y S11^-1`` (mean-square stabilisable), and
- ``A^T P11 + P11 A + Z C + C^T Z^T + W^T P11 W < 0`` with ``Z = P11 B Dc + P12 Bc``: ``(A - L C, W)`` is
  mean-square stable for ``L = -P11^-1 Z`` (mean-square detectable).

Both are LMIs, homogeneous in the unknowns and monotone in the diffusion's scale s. Where a rule fails either at
the plant's diffusion, no controller of any structure certifies it (and the T-S certificates, which make every
rule's frozen loop mean-square stable, cannot exist): the plant, not the method. :func:`limits` names the largest
scale each rule allows. Theorem 3's diffusion only (``W x``): with ``G u`` in the diffusion the controller's own
noise enters and the two conditions are not the necessary pair.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._augment import Augmented, time_scale
from ..core._linalg import sym as _sym
from ..core._sdp import SOLVED, ConicProblem, Layout, Var, affine_lmi

__all__ = ["limits", "Limit", "describe", "decide"]

#: the margin of the decisions, relative to the normalisation ``S >= I`` in the plant's own time
MARGIN = 1e-6
#: bisection steps in log s between 1e-3 and 1 (a bracket 7 % wide)
STEPS = 7


@dataclass(frozen=True)
class Limit:
    """Rule ``rule`` (0-based) is not mean-square ``kind`` ("stabilisable" or "detectable") with its diffusion
    scaled by ``infeasible`` (decided infeasible by the solver), and is with ``feasible`` (0: not even at 1e-3)."""

    rule: int
    kind: str
    feasible: float
    infeasible: float


def describe(found: list[Limit]) -> str:
    """The sentence a refusal carries: the tightest limit of each kind, with the rules that share it."""
    parts = []
    for kind in ("stabilisable", "detectable"):
        mine = [lim for lim in found if lim.kind == kind]
        if not mine:
            continue
        worst = min(mine, key=lambda lim: lim.feasible)
        rules = [lim.rule + 1 for lim in mine if lim.feasible == worst.feasible]
        who = (
            f"rule {rules[0]}'s local model is"
            if len(rules) == 1
            else f"the local models of rules {rules} are"
        )
        keep = f"{100 * worst.feasible:.2g} %" if worst.feasible > 0 else "0.1 %"
        via = "the inputs" if kind == "stabilisable" else "the outputs"
        parts.append(f"{who} not mean-square {kind} with more than {keep} of the diffusion (infeasible at s = "
                     f"{worst.infeasible:.3g}): no linear feedback through {via}, this observer-based one or any "
                     "other, makes it mean-square stable")  # fmt: skip
    return "; ".join(parts)


def decide(aug: Augmented, i: int, kind: str, s: float, solver: str) -> bool | None:
    """Is rule i ``kind`` with the diffusion scaled by ``s``? Posed in the plant's own time (drift times tau,
    diffusion times sqrt(tau): the same question), ``S >= I`` and the LMI below ``-MARGIN I``; a point is checked
    with numpy, infeasibility is the solver's status; None: undecided."""
    n = aug.n
    tau = time_scale(aug)
    A = tau * aug.Abar[i][:n, :n]
    W = s * math.sqrt(tau) * aug.Wbar[i][:n]
    eye = np.eye(n)
    if kind == "stabilisable":
        B = tau * aug.Bbar[i][:n]
        layout = Layout(Var("S", (n, n), True), Var("Y", (B.shape[1], n)))

        def main(S, Y):
            return np.block([[A @ S + S @ A.T + B @ Y + Y.T @ B.T + MARGIN * eye, W @ S], [S @ W.T, -S]])
    else:
        C = aug.Cbar[:, :n]
        layout = Layout(Var("S", (n, n), True), Var("Y", (n, C.shape[0])))

        def main(S, Y):  # S is P, Y is Z
            return np.block([[A.T @ S + S @ A + Y @ C + C.T @ Y.T + MARGIN * eye, W.T @ S], [S @ W, -S]])

    lmis = [affine_lmi(kind, layout, main), affine_lmi("S >= I", layout, lambda S, Y: eye - S)]
    res = ConicProblem(layout, lmis).solve(solver)
    if res.infeasible:
        return False
    if res.v is None or res.status not in SOLVED:
        return None
    u = layout.unpack(res.v)
    M = _sym(main(u["S"], u["Y"])) - MARGIN * np.diag(np.r_[np.ones(n), np.zeros(n)])
    return bool(np.linalg.eigvalsh(M)[-1] < 0 and np.linalg.eigvalsh(u["S"])[0] > 0)


def limits(aug: Augmented, solver: str = "CLARABEL") -> list[Limit]:
    """The rules that are not mean-square stabilisable or detectable with the plant's whole diffusion, each with
    the bracket of the largest scale at which it is (bisection in log s between 1e-3 and 1); empty where every
    rule is both, where a decision failed, or where the diffusion is not Theorem 3's ``W x`` alone."""
    if any(np.any(G) for G in aug.Gbar) or any(np.any(W) for W in aug.Gfbar) or aug.Mbar[0].shape[1]:
        return []
    out = []
    for i in range(aug.r):
        if not np.any(aug.Wbar[i]):
            continue
        for kind in ("stabilisable", "detectable"):
            if decide(aug, i, kind, 1.0, solver) is not False:
                continue
            lo, hi = 1e-3, 1.0
            at_lo = decide(aug, i, kind, lo, solver)
            if at_lo is None:
                continue
            if at_lo is False:
                out.append(Limit(i, kind, 0.0, lo))
                continue
            for _ in range(STEPS):
                mid = math.sqrt(lo * hi)
                got = decide(aug, i, kind, mid, solver)
                if got is None:
                    break
                lo, hi = (mid, hi) if got else (lo, mid)
            out.append(Limit(i, kind, lo, hi))
    return out
