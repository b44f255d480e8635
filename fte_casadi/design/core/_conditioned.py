"""The conditioned design (the default): the printed LMIs, posed to be well scaled, unique and cheap.

The certificate is exactly the printed one ((45), (46), (55), (64), or (78)-(81) for Theorem 5,
recomputed at the end by :func:`fte_casadi.design.core._certify.certificate`); what changes is how the
solver is asked for a point. Every choice below is an equivalent reformulation or an added
constraint, never a changed certificate.

Step 3 — LMI (45) for X and the gains
    *Common gain.* (45) has no term coupling different gains: a Y_j that satisfies (45) for
    every rule i is itself a valid gain for every j, so one gain ``K`` (``K_j = K``) loses
    nothing and gives r LMIs instead of r^2 near-duplicates.
    *Input scaling.* ``u = Su u~`` with ``Su`` making every column of B unit length (the
    three-tank's B entries are 6.5e-3): ``B Y = (B Su)(Su^-1 Y)``, an exact change of variables.
    *Homogenisation.* ``X = X'/s, Y = Y'/s``; ``s (45)(X'/s, Y'/s)`` is affine in ``(X', Y', s)``
    (the builders multiply their constant terms by ``s``), so the scale of X is an unknown of
    the one solve, and ``I <= X' <= 1e4 I`` bounds cond(X) without fixing its size.
    *Objective.* ``min t`` with ``||Y'||_2 <= t``: since ``X' >= I``, ``||K~|| <= t`` — the
    smallest gain the LMI allows, which keeps K implementable.

Step 5 — LMIs (46), (55), (64) for Pbar, Q_i, N, theta
    *Congruence by X*: ``diag(X, I) (46) diag(X, I)`` turns ``-sigma P P`` into ``-sigma I``
    and ``-P Be`` into ``-Be``, so the fixed P = X^-1 no longer enters squared.
    *Finsler*: for a given Pbar, ``-Q_i Cbar - Cbar^T Q_i^T`` can be restricted to
    ``Q_i = rho_i Cbar^T / 2`` without losing feasibility (Finsler's lemma), so the observer
    gains are ``L_i1 = (rho_i / 2) Pbar^-1 Cbar^T``.
    *N eliminated*: for a given Pbar, ``N = J1^T T^T Pbar Cbar^+`` is the exact minimiser of
    ``||J1^T T^T Pbar - N Cbar||_2``, the mismatch of (55).
    *Homogenisation*: ``Pbar = Pt/s`` with ``I <= Pt <= kappa I`` (kappa = 1e4 bounds
    cond(Pbar)); (55) and (64) in the balanced form ``||E(Pt)|| <= tau`` so that
    ``theta = (tau/s)^2``; the scale of Pbar is an unknown instead of a grid.
    *Decay rate*: ``2 alpha Pbar`` in the (3,3) block makes every R_i decay at least as fast as
    ``exp(-alpha t)``; alpha is a DPP parameter (re-solved without re-canonicalisation).
    *Objective*: ``min sy^2 sum_i rho_i + tau`` (observer gain scale and sliding mismatch, both in
    the normalised units of Pt; ``sy`` the outputs' size, :func:`~fte_casadi.design._augment.output_scale`,
    so that the balance does not depend on the outputs' unit).
    *Observer speed*: by default alpha is ``ALPHA_FRACTION`` times the largest alpha for which
    (46) is feasible with ``I <= Pt <= kappa I`` (found by bisection, each trial one solve of the
    same problem), lowered when needed so that ``ts_max >= TS_FACTOR * sample_time``.

Margins are per diagonal block and relative to that block's own size (``MARGIN`` of sigma, of
gamma1^2, of Pt >= I, ...; ``2 MARGIN`` in the conic solve, ``MARGIN`` in the centring, so that
the solver's point starts the centring strictly inside). After each conic solve,
:func:`fte_casadi.design.core._barrier.centre` moves to the unique central-path point with relative gap
``ETA``: the design is a smooth function of the plant and does not depend on the solver or the
machine beyond round-off.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..._rounding import nice_floor
from ...errors import CentringError, InfeasibleDesignError, Refused
from ...errors import SolverFailedError as SolverFailedError
from .._augment import (
    Augmented,
    output_scale,
    time_scale,
    units_params,
    units_scaled,
)
from ._barrier import centre, numpy_first, phase1
from ._decay import ALPHA_RTOL as ALPHA_RTOL
from ._decay import TS_FACTOR, alpha_max, loop_decay_target
from ._lmis import (
    STEP3,
    Posed,
    balanced,
    balanced_margin,
    loop_decay,
    posed,
)
from ._sdp import (
    SOLVED,
    AffineLMI,
    ConicProblem,
    Layout,
    MarginLMI,
    SolveResult,
    Var,
    affine_lmi,
    margin_lmi,
)

__all__ = ["Step3", "Step5", "step3", "input_scaling", "alpha_max", "MARGIN", "KAPPA", "ETA",
           "ALPHA_FRACTION", "TS_FACTOR", "SolverFailedError"]  # fmt: skip

#: relative margin of every diagonal block (the conic solve uses twice this)
MARGIN = 1e-3
#: bound on cond(X') and cond(Pt) (the normalised X and Pbar)
KAPPA = 1e4
#: relative duality gap of the centred point
ETA = 0.5
#: default observer decay rate as a fraction of the largest feasible one
ALPHA_FRACTION = 0.9
#: phase 1 bounds the gains by rho_i <= RHO_CAP kappa max ||T Abar_i|| / sigma_min(Cbar)^2 (never active in a design)
RHO_CAP = 1e3


def _kappa(params: dict) -> float:
    """The bound on cond(X') and cond(Pt): ``params["kappa"]`` when the design was asked for one, else KAPPA."""
    return float(params.get("kappa", KAPPA))


@dataclass
class Step3:
    X: np.ndarray
    K: np.ndarray
    status: str
    solves: int
    seconds: float
    notes: list = field(default_factory=list)
    #: the closed loop's decay rate the LMI "decay" certifies, and why it is what it is
    beta: float = 0.0
    beta_why: str = ""
    #: True when the rate's LMI was posed (the gain is not the smallest of (45) alone); the default's lower rate
    posed: bool = False
    low: float = 0.0
    #: the bound on cond(X') this X was designed under
    kappa: float = KAPPA


@dataclass
class Step5:
    Pbar: np.ndarray
    Q: list
    N: np.ndarray
    theta: float
    alpha: float
    status: str
    solves: int
    seconds: float
    observer: dict
    notes: list = field(default_factory=list)
    #: the block-diagonal certificate of the fault-error bound when it was in the objective (bound_objective)
    bound: dict | None = None
    #: the bound on cond(Pbar) this observer was designed under
    kappa: float = KAPPA
    #: Theorem 1's loop block of V where the observer was designed by (29) (``joint``), else None
    P29: np.ndarray | None = None


def input_scaling(aug: Augmented) -> np.ndarray:
    """``Su``: diagonal, making the largest column norm of the B_i of each input 1 (1 for a zero column)."""
    norms = np.max([np.linalg.norm(B[: aug.n], axis=0) for B in aug.Bbar], axis=0)
    return np.diag(np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0))


def _normalisation(layout: Layout, name: str, size: int, kappa: float = KAPPA) -> list[MarginLMI]:
    eye = np.eye(size)
    return [
        margin_lmi(f"{name} >= I", layout, lambda **u: eye - u[name], margin=lambda **u: eye,
                   support=layout.support(name), kron=(name, [(eye, -0.5 * eye)])),
        margin_lmi(f"{name} <= {kappa:g} I", layout, lambda **u: u[name] - kappa * eye,
                   margin=lambda **u: kappa * eye, support=layout.support(name), kron=(name, [(eye, 0.5 * eye)])),
    ]  # fmt: skip


def _accept(res: SolveResult, lmis, p: float) -> bool:
    """A solver's point counts when it is strictly inside ``lmis`` (the LMIs with the centring's
    margins, half the conic solve's), checked with numpy, whatever the solver's status says."""
    if res.v is None or res.status not in SOLVED or not np.all(np.isfinite(res.v)):
        return False
    for L in lmis:
        try:
            np.linalg.cholesky(-L.value(res.v, p))
        except np.linalg.LinAlgError:
            return False
    return True


def _into_normalisation(layout: Layout, v: np.ndarray, name: str, kappa: float = KAPPA) -> np.ndarray:
    """``v`` with the eigenvalues of the normalised matrix ``name`` clipped into ``[1 + 3 MARGIN, KAPPA (1 - 3 MARGIN)]``.

    A first-order solver's point can miss the normalisation by its tolerance; after this, the
    normalisation holds strictly and phase 1 can take the point as it is.
    """
    u = layout.unpack(v)
    w, V = np.linalg.eigh(u[name])
    M = (V * np.clip(w, 1 + 3 * MARGIN, kappa * (1 - 3 * MARGIN))) @ V.T
    out = v.copy()
    n = M.shape[0]
    out[layout.index(name)] = M[np.triu_indices(n)]
    return out


def _start(
    res: SolveResult, layout: Layout, name: str, soft, hard, note: list, kappa: float = KAPPA
) -> np.ndarray | None:
    """A strictly feasible point of ``soft`` and ``hard`` from the solver's answer, or None.

    The solver's point is taken if it is strictly feasible; otherwise (an approximate point, e.g.
    SCS at its tolerance) its normalisation is repaired and :func:`~fte_casadi.design.core._barrier.phase1`
    decides, in numpy, from there. A status that is neither a point nor infeasibility is a failure.
    """
    if res.v is None or res.status not in SOLVED or not np.all(np.isfinite(res.v)):
        return None
    if _accept(res, list(soft) + list(hard), 0.0):
        return res.v
    v = _into_normalisation(layout, res.v, name, kappa)
    try:
        out = phase1(list(soft), list(hard), v)
    except CentringError:
        return None
    if out is not None:
        note.append(
            f"the solver's point ({res.status}) missed the LMIs by its tolerance; phase 1 in numpy repaired it"
        )
    return out


def worst_block(lmis, blocks: dict[int, list[tuple[str, int]]]) -> tuple[str, float, float] | None:
    """The diagonal block whose data (constant term and the coefficients of every unknown, in the rows of
    that block) spans the most orders of magnitude, over ``lmis``: ``(where, smallest, largest)`` of its
    nonzero magnitudes. ``blocks[k]`` names the blocks of an LMI of size k as ``[(name, rows), ...]``."""
    worst = None
    for L in lmis:
        start = 0
        for name, rows in blocks.get(L.k, [("", L.k)]):
            r = slice(start, start + rows)
            start += rows
            vals = np.abs(np.concatenate([L.F0[r].ravel(), L.F[:, r].ravel()]))
            vals = vals[vals > 1e-300]
            if not vals.size:
                continue
            lo, hi = float(vals.min()), float(vals.max())
            if worst is None or hi / lo > worst[2] / worst[1]:
                worst = (f"{L.name}, {name} rows" if name else L.name, lo, hi)
    return worst


def _fail(
    step: str, res: SolveResult, solver: str, hint: str, spread=None, lmi: str | None = None
) -> InfeasibleDesignError | SolverFailedError:
    solver = res.solver or solver
    if res.infeasible:
        return InfeasibleDesignError(f"{step} is infeasible ({solver}: {res.status}); {hint}", lmi=lmi,
                                     bounded=lmi is not None)  # fmt: skip
    other = "SCS" if solver == "CLARABEL" else "CLARABEL"
    data = ""
    if spread is not None:
        where, lo, hi = spread
        data = (f" The worst-scaled block the solver saw ({where}) holds numbers from {lo:.2g} to {hi:.2g}, "
                f"{np.log10(hi / lo):.0f} orders of magnitude.")  # fmt: skip
    return SolverFailedError(
        f"{step}: the solver {solver} failed numerically ({res.status}), also on rescaled data; this is a "
        f"numerical failure, not a proof of infeasibility: try solver='{other}', or {hint}.{data}"
    )


# -- step 3 ----------------------------------------------------------------------------------
def _step3_problem(aug: Augmented, params: dict, Su: np.ndarray):
    """Step 3's LMIs in ``(X', Y', s, t)``: the registered ones posed in it (:func:`~._lmis.posed`: (45) and the
    decay LMI per rule, soft, first), the normalisation of X', then the epigraph of ``t`` (``min t``)."""
    n, m = aug.n, aug.m
    layout = Layout(Var("X", (n, n), True), Var("Y", (m, n)), Var("s", ()), Var("t", ()))
    lmis = posed(STEP3, Posed(aug, params, layout, Su=Su))
    lmis += _normalisation(layout, "X", n, _kappa(params))
    lmis.append(margin_lmi("||Y'|| <= t", layout, lambda X, Y, s, t: balanced(Y, t),
                           margin=lambda X, Y, s, t: balanced_margin(t, m, n)))  # fmt: skip
    c = np.zeros(layout.size)
    c[layout.index("t")] = 1.0
    return layout, lmis, c


def _soft(family) -> int:
    """How many of step 3's LMIs (:func:`_step3_problem`, with or without its epigraph) are soft: the registered
    ones posed in it (every one of them is, :func:`~._lmis.register`), all before the normalisation of X'."""
    return [getattr(L, "base", L).name for L in family].index("X >= I")


def _step3_conic(aug: Augmented, params: dict, solver: str, tau: float, layout: Layout, Su: np.ndarray):
    """The feasibility solve of step 3, posed in the time ``t / tau`` with outputs divided by ``sy``
    (:func:`~fte_casadi.design._augment.units_scaled`), its point mapped back exactly to the unknowns of the
    unscaled problem (``X = X~ / (tau sy^2)``, the same K).

    Only the starting point comes from here: the centring that follows runs on the unscaled LMIs, and
    Newton's method is invariant under such changes of variables, so the design does not depend on tau.
    """
    # d in the size of gamma (gamma~ = 1): the d block's numbers of order one whatever unit d is in, and the
    # same numbers for the same plant with d in another unit (gamma scales with it, as the generic one does)
    sy = output_scale(aug)
    sd = params["gamma"] / sy
    aug_s = units_scaled(aug, tau, sy, sd)
    params_s = units_params(params, tau, sy, sd)
    params_s["beta"] = tau * float(params.get("beta", 0.0))  # a rate, in the scaled time
    Su_s = input_scaling(aug_s)
    layout_s, family_s, _ = _step3_problem(aug_s, params_s, Su_s)
    prob = ConicProblem(layout_s, [L.at(2 * MARGIN) for L in family_s[:-1]])  # without the epigraph of t
    res = prob.solve(solver)
    if (tau == 1.0 and sy == 1.0 and sd == 1.0) or res.v is None or not np.all(np.isfinite(res.v)):
        return prob, res
    u = layout_s.unpack(res.v)
    try:
        K = Su_s @ u["Y"] @ np.linalg.inv(u["X"])
    except np.linalg.LinAlgError:
        return prob, replace(res, v=None)
    v = layout.pack(X=u["X"], Y=np.linalg.solve(Su, K @ u["X"]), s=tau * sy**2 * u["s"], t=0.0)
    return prob, replace(res, v=v)


def _scalar_cap(layout: Layout, name: str, hi: float) -> list[AffineLMI]:
    """``0 < v[name] <= hi`` as two 1 x 1 LMIs."""
    F = np.zeros((layout.size, 1, 1))
    F[layout.index(name), 0, 0] = 1.0
    return [AffineLMI(f"{name} <= cap", np.array([[-hi]]), F), AffineLMI(f"{name} > 0", np.zeros((1, 1)), -F)]


def _step3_numpy(aug: Augmented, params: dict, layout: Layout, feas: list, keep_infeasible: bool = False):
    """A heavy step 3's start point by phase 1 in numpy (:func:`~fte_casadi.design.core._barrier.numpy_first`),
    or None (then the conic solvers).

    (45) is a cone in ``(X', Y', s)`` cut by ``I <= X' <= kappa I``; phase 1's barrier pushes along the
    cone towards the upper normalisation, so it starts there (``X' = kappa/2 I``, ``s = 1``, ``Y' = 0``;
    from ``X' = sqrt(kappa) I`` the damped Newton steps creep up the ray 0.25 % at a time). Phase 1 needs
    a bounded set: ``||Y'|| <= RHO_CAP kappa max(max ||A_i||, sigma)`` (a gain ``||K~||`` of RHO_CAP times
    the plant's fastest rate) and ``0 < s <= `` that cap times ``max(1, 1/sigma, ||C||^2)``. The caps only
    serve phase 1: an answer "infeasible" under them goes to the conic solver, which has none (returned,
    with ``keep_infeasible``, where the conic solver has already failed numerically).
    """
    n, m = aug.n, aug.m
    kappa = _kappa(params)
    prob = ConicProblem(layout, feas)
    v0 = layout.pack(X=0.5 * kappa * np.eye(n), Y=np.zeros((m, n)), s=1.0, t=0.0)
    res = numpy_first(prob, _soft(feas), v0, _step3_caps(aug, params, layout))
    if res is None or (res.v is None and not keep_infeasible):
        return None
    return prob, res


def _step3_caps(aug: Augmented, params: dict, layout: Layout) -> list[AffineLMI]:
    """The bounds phase 1 needs on step 3's cone (:func:`_step3_numpy`): ``||Y'|| <= RHO_CAP kappa max(max
    ||A_i||, sigma)`` and ``0 < s <=`` that cap times ``max(1, 1/sigma, ||C||^2)``."""
    n = aug.n
    kappa, sg = _kappa(params), float(params["sigma"])
    a = max(np.linalg.norm(A[:n, :n], 2) for A in aug.Abar)
    ycap = RHO_CAP * kappa * max(a, sg, 1e-300)
    scap = ycap * max(1.0, 1.0 / max(sg, 1e-300), np.linalg.norm(aug.Cbar[:, :n], 2) ** 2)
    ycap_lmi = affine_lmi(
        "||Y'|| <= cap", layout, lambda X, Y, s, t: balanced(Y, ycap), support=layout.support("Y")
    )
    return [ycap_lmi] + _scalar_cap(layout, "s", scap)


def _step3_start(aug: Augmented, params: dict, solver: str, Su: np.ndarray, tau: float):
    """``(layout, family, c, prob, res, v0)``: step 3's problem at ``params`` (its ``beta`` the decay rate asked)
    and a strictly feasible start for its centring, or the error of an infeasible or failed (45)."""
    layout, family, c = _step3_problem(aug, params, Su)
    feas = [L.at(2 * MARGIN) for L in family[:-1]]  # without the epigraph of t
    first = _step3_numpy(aug, params, layout, feas) if ConicProblem(layout, feas).heavy else None
    if first is not None:
        prob, res = first
    else:
        prob, res = _step3_conic(aug, params, solver, tau, layout, Su)
        if res.failed:  # a numerical failure of the solver: phase 1 in numpy decides instead
            fallback = _step3_numpy(aug, params, layout, feas, keep_infeasible=True)
            if fallback is not None:
                fallback[0].notes.insert(
                    0, f"{solver} failed numerically ({res.status}); phase 1 in numpy decided"
                )
                prob, res = fallback
    g, g1, sg = params["gamma"], params["gamma1"], params["sigma"]
    lmis = [L.at(MARGIN) for L in family]
    repaired: list[str] = []
    k = _soft(family)
    v0 = _start(res, layout, "X", lmis[:k], lmis[k : k + 2], repaired, _kappa(params))
    if v0 is None:
        hint = f"see the bounds on gamma and sigma (gamma = {g:g}, gamma1 = {g1:g}, sigma = {sg:g})"
        n, p, ld = aug.n, aug.p, aug.ld
        names = {2 * n + p + ld: [("x", n), ("x (diffusion)", n), ("y", p), ("d", ld)]}
        what = "LMI (45)" + (
            f" with the closed loop's decay rate beta = {params['beta']:.4g}" if params.get("beta") else ""
        )
        raise _fail(what, res, solver, hint, worst_block(prob.lmis, names), lmi="45")
    prob.notes += [f"step 3: {r}" for r in repaired]
    return layout, family, c, prob, res, v0


def _beta_max(
    aug: Augmented, params: dict, Su: np.ndarray, v0: np.ndarray, hi: float
) -> tuple[float, np.ndarray]:
    """``(lo, v)``: (45) with the decay term holds strictly at ``beta = lo`` (at the point ``v``), decided by phase 1
    in numpy from ``v0`` (a point at a smaller beta), by bisection in log scale below ``hi`` (where it does not
    hold) to :data:`~._decay.ALPHA_RTOL`; ``lo`` starts at what ``v0`` itself reaches."""
    layout = _step3_problem(aug, dict(params, beta=0.0), Su)[0]
    caps = _step3_caps(aug, params, layout)

    def point(b: float, start: np.ndarray) -> np.ndarray | None:
        fam = _step3_problem(aug, dict(params, beta=b), Su)[1]
        lm = [L.at(MARGIN) for L in fam]
        k = _soft(fam)
        try:
            return phase1(lm[:k], lm[k : k + 2] + caps, start)
        except CentringError:
            return None

    u = layout.unpack(v0)
    lo = min(max(loop_decay(aug, u["X"], [Su @ u["Y"] @ np.linalg.inv(u["X"])]) / (1 + 2 * MARGIN), 0.0), hi)
    v = v0
    while hi > max(lo, 1e-12 * hi) * (1 + ALPHA_RTOL):
        mid = float(np.sqrt(lo * hi)) if lo > 0 else hi / 8
        w = point(mid, v)
        if w is None:
            hi = mid
            if lo == 0 and hi < 1e-6 * abs(mid) + 1e-300:
                break
        else:
            lo, v = mid, w
    return lo, v


def step3(
    aug: Augmented, params: dict, solver: str, *, beta: float | None = None, why: str | None = None
) -> Step3:
    """Step 3 (conditioned): one common gain K and X from (45)/(78); see the module docstring.

    One feasibility solve gives a strictly feasible point (for a problem with many PSD cones, phase 1 in
    numpy, :func:`_step3_numpy`; the conic solvers when it finds none);
    :func:`~fte_casadi.design.core._barrier.centre` then minimises ``t`` along the central path to the unique
    centred point, which does not depend on where it started.

    The loop is asked to decay at least at ``beta``: the LMI :func:`~._lmis.lmi_decay` with the same X and Y
    (``x^T X^-1 x`` decreases at least as ``exp(-2 beta t)`` for any blending of the rules). Given, a rate is
    refused where (45) does not allow it; by default (``None``) it is :func:`~._decay.loop_decay_target` (twice
    the open loop's slowest decay rate, or as fast as it diverges), lowered to ``ALPHA_FRACTION`` of the largest
    rate (45) allows with it at these parameters where that is slower. The smallest gain of (45) alone is kept
    where it meets the rate (then the rate LMI is not posed, and the design is the one without it); otherwise
    the smallest gain is sought among the gains that make the loop that fast: never the gain 0 of a stable plant.
    """
    Su = input_scaling(aug)
    tau = time_scale(aug)
    layout, family, c, prob, res, v0 = _step3_start(aug, dict(params, beta=0.0), solver, Su, tau)
    if beta is not None and beta > 0:  # the user's rate: posed, refused where (45) does not allow it
        return _step3_at(
            aug,
            params,
            solver,
            Su,
            tau,
            float(beta),
            why or "set by the user",
            v0,
            refuse=True,
            asked=why is None,
        )
    if beta is not None:
        return _step3_result(aug, params, Su, layout, _centre3(aug, layout, family, c, res, v0), prob, res, solver,
                             0.0, why or "set by the user: no rate asked")  # fmt: skip
    # the default: the smallest gain of (45) alone where its loop is already fast enough (the rate's LMI is posed
    # only where it binds: posed, it would move the centred point even where it does not)
    (high, low), why = loop_decay_target(aug)
    cen0 = _centre3(aug, layout, family, c, res, v0)
    u = layout.unpack(cen0.v)
    X0, K0 = u["X"] / u["s"], Su @ u["Y"] @ np.linalg.inv(u["X"])
    fast0 = min(-float(np.max(np.linalg.eigvals(A[: aug.n, : aug.n] + B[: aug.n] @ K0).real))
                for A, B in zip(aug.Abar, aug.Bbar))  # fmt: skip
    certified0 = loop_decay(aug, X0, [K0]) * (1 - 4 * MARGIN)
    if high <= 0 or fast0 >= high:
        return _step3_result(aug, params, Su, layout, cen0, prob, res, solver, certified0,
                             f"{why}; met by the smallest gain (45) allows: its loop decays at {fast0:.4g} per rule, "
                             f"at {certified0:.4g} for any blending (the rate recorded)")  # fmt: skip
    try:
        out = _step3_at(aug, params, solver, Su, tau, high, why, v0, refuse=low < high)
    except (InfeasibleDesignError, SolverFailedError):
        if fast0 >= low:
            return _step3_result(aug, params, Su, layout, cen0, prob, res, solver, certified0,
                                 f"{why}, infeasible with (45) at these parameters; the smallest gain (45) allows decays "
                                 f"at {fast0:.4g} per rule (>= {low:.4g}, no slower than asked at least), at "
                                 f"{certified0:.4g} for any blending (the rate recorded)")  # fmt: skip
        out = _step3_at(aug, params, solver, Su, tau, low, why + f"; {high:.4g} is infeasible with (45) at these "
                        f"parameters, so at least {low:.4g}", v0, refuse=False)  # fmt: skip
    out.low = low if out.beta > low else 0.0
    return out


def _step3_at(aug, params, solver, Su, tau, target: float, why: str, v_low, *, refuse: bool,
              asked: bool = False) -> Step3:  # fmt: skip
    """Step 3 with the closed loop asked to decay at ``target``; where (45) does not allow it, refused (``refuse``;
    ``asked``: the user asked for the rate, and the refusal says what (45) allows) or at ``ALPHA_FRACTION`` of the
    largest rate it allows (by bisection from ``v_low``, a point of (45) alone)."""
    try:
        layout, family, c, prob, res, v0 = _step3_start(aug, dict(params, beta=target), solver, Su, tau)
    except (InfeasibleDesignError, SolverFailedError):
        if refuse and asked:
            lo, _ = _beta_max(aug, params, Su, v_low, target)
            raise InfeasibleDesignError(
                f"LMI (45) with the closed loop's decay rate beta = {target:g} is infeasible at sigma = "
                f"{params['sigma']:g}, gamma = {params['gamma']:g}: the largest rate it allows there is about "
                f"{lo:.4g}; lower beta to <= {nice_floor(ALPHA_FRACTION * lo):g} (or leave it unset for the default)",
                kind=Refused.DECAY_RATE,
                lmi="45",
                numbers={"beta": target, "beta_max": lo},
            ) from None
        if refuse:
            raise
        lo, v0 = _beta_max(aug, params, Su, v_low, target)
        target = ALPHA_FRACTION * lo
        why += (f"; lowered to {ALPHA_FRACTION:g} x the largest decay rate (45) allows with it at these parameters "
                f"(about {lo:.4g}, by bisection)")  # fmt: skip
        layout, family, c = _step3_problem(aug, dict(params, beta=target), Su)
        prob, res = None, SolveResult("phase 1 (numpy)", v0, 0.0)
    cen = _centre3(aug, layout, family, c, res, v0)
    out = _step3_result(aug, params, Su, layout, cen, prob, res, solver, target, why)
    out.posed = True
    return out


#: the Newton budget of step 3's centring: a start from phase 1 in numpy near (45)'s boundary (the 64-rule chain at
#: 0.8-0.9 of its sigma_max) needs more than 400 damped steps, and converges within this; a converging centring stops
#: at its fixed point, so only a failing one spends it all
CENTRE3_STEPS = 2000


def _centre3(aug: Augmented, layout: Layout, family: list, c: np.ndarray, res: SolveResult, v0: np.ndarray):
    """The centred point of step 3 from the strictly feasible ``v0``."""
    v0 = v0.copy()  # t starts well above ||Y'||: the epigraph is then strictly feasible
    v0[layout.index("t")] = 2.0 * np.linalg.norm(layout.unpack(v0)["Y"], 2) + 1.0
    lmis = [L.at(MARGIN) for L in family]
    floor = 0.01 * max(np.linalg.norm(A[: aug.n, : aug.n], 2) for A in aug.Abar)
    try:
        return centre(lmis, c, v0, eta=ETA, floor=floor, max_steps=CENTRE3_STEPS)
    except CentringError as exc:
        raise SolverFailedError(
            f"step 3: the centring of the solver's point failed ({exc}); try the other solver"
        ) from None


def _step3_result(aug, params, Su, layout, cen, prob, res, solver, b, why) -> Step3:
    """The Step3 record of the centred point ``cen`` (the rate asked ``b``, and why)."""
    if prob is None:  # the start came from the bisection's phase 1
        prob = ConicProblem(layout, [])
    u = layout.unpack(cen.v)
    X = u["X"] / u["s"]
    K = Su @ u["Y"] @ np.linalg.inv(u["X"])
    notes = [
        f"step 3: one common gain K (K_j = K), inputs scaled by Su = diag({', '.join(f'{v:.4g}' for v in np.diag(Su))}), "
        f"X = X'/s with I <= X' <= {_kappa(params):g} I, min ||Y'|| with the closed loop's decay rate beta = {b:.4g} "
        f"({why}): {prob.solves} feasibility solve ({res.status}"
        + (", on rescaled data" if res.rescaled else "") + f"), then {cen.newton_steps} Newton steps to the centred "
        f"point (gap {ETA:g} of the objective)"
    ]  # fmt: skip
    notes += [f"step 3: {solver} warned: {w!r}" for w in res.warned]
    notes += [f"step 3: {x}" if not x.startswith("step 3: ") else x for x in prob.notes]
    return Step3(
        X, K, res.status, prob.solves, prob.seconds, notes, beta=b, beta_why=why, kappa=_kappa(params)
    )
