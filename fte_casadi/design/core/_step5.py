"""Step 5 of the conditioned design: the observer by (46) (or Theorem 1's (29) at step 3's gain), (55) and (64).

How it is posed (the congruence by X, Finsler's ``Q_i = rho_i Cbar^T / 2``, N eliminated, the homogenisation of
Pbar, the decay rate ``alpha`` as a parameter, the objective) is said in :mod:`._conditioned`, which holds what
steps 3 and 5 share (the margins, the normalisation, the records, the refusals' messages); the LMIs themselves
come from the registry (:func:`~._lmis.posed`).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from ..._rounding import nice_floor
from ..._text import shorten
from ...errors import CentringError, InfeasibleDesignError, Refused, SolverFailedError
from .._augment import (
    Augmented,
    output_scale,
    time_scale,
    time_scaled,
)
from ._barrier import centre, numpy_first, phase1_active
from ._bound_objective import bound_term
from ._certify import lyapunov_ts_max, ts_max
from ._conditioned import (
    ALPHA_FRACTION,
    ETA,
    MARGIN,
    RHO_CAP,
    Step5,
    _fail,
    _kappa,
    _normalisation,
    _start,
    worst_block,
)
from ._decay import TS_FACTOR, alpha_max, cap_for_sample_time
from ._lmis import (
    JOINT,
    STEP5,
    Posed,
    diffusion_coupling,
    posed,
    sliding_mismatch,
)
from ._sdp import (
    AffineLMI,
    ConicProblem,
    Layout,
    SolveResult,
    Var,
    margin_lmi,
)

__all__ = ["step5", "P1_CAP"]


def _step5_problem(aug: Augmented, params: dict, X, K, T, *, rest: bool = True, joint: bool = False):
    """The registered LMIs posed in step 5 (:func:`~._lmis.posed`: (46) per rule) and the normalisation (the
    feasibility part), then those of its rest ((55), (64) per rule) and the objective.

    ``joint``: Theorem 1's (29) instead of (46) (:func:`~._lmis.lmi29`), with the loop's Lyapunov matrix an unknown
    too (``P29 = P1t / s``) instead of step 3's ``P = X^-1`` and without sigma; the feasibility part then also holds
    ``0 < P1t <= P1_CAP kappa I`` (bounded for phase 1)."""
    if joint:
        return _step5_joint(aug, params, K, T, rest=rest)
    layout = Layout(Var("Pt", (aug.nbar, aug.nbar), True), Var("s", ()), Var("rho", (aug.r,)), Var("tau", ()))
    at = Posed(aug, params, layout, K=K, T=T, X=X)
    feas = posed(STEP5, at) + _normalisation(layout, "Pt", aug.nbar, _kappa(params))
    if not rest:  # the feasibility solve needs (46) and the normalisation only
        return layout, feas, [], None
    return layout, feas, posed(STEP5, at, "rest"), _objective(aug, layout)


#: phase 1 bounds the loop's block of Theorem 1's V by P1t <= P1_CAP kappa I (Pt, the observer's, lies in [I, kappa I])
P1_CAP = 1e6


def _step5_joint(aug: Augmented, params: dict, K, T, *, rest: bool = True):
    """Theorem 1's (29) per rule at the gain K, in ``(P1t, Pt, s, rho)`` (``P29 = P1t / s``, ``Pbar = Pt / s``,
    ``Q_i = rho_i Cbar^T / (2 s)``: homogenised as (46); :func:`~._lmis.posed`), the normalisation of Pt and
    ``0 < P1t <= P1_CAP kappa I``, then (55), (64) per rule, and ``s > 0``."""
    n, nbar, r = aug.n, aug.nbar, aug.r
    kappa = _kappa(params)
    layout = Layout(Var("Pt", (nbar, nbar), True), Var("P1", (n, n), True), Var("s", ()), Var("rho", (r,)),
                    Var("tau", ()))  # fmt: skip
    at = Posed(aug, params, layout, K=K, T=T)
    feas = posed(JOINT, at) + _normalisation(layout, "Pt", nbar, kappa)
    eye = np.eye(n)
    cap = P1_CAP * kappa
    # s > 0 (Pbar = Pt / s > 0): without unknown inputs nothing else in (29) asks it (in (46) the x block's -sigma s I does)
    feas += [margin_lmi("s > 0", layout, lambda **u: -u["s"] * np.eye(1), support=layout.support("s"))]
    feas += [
        margin_lmi("P1t > 0", layout, lambda **u: -u["P1"], margin=lambda **u: eye, support=layout.support("P1")),
        margin_lmi(f"P1t <= {cap:g} I", layout, lambda **u: u["P1"] - cap * eye, margin=lambda **u: cap * eye,
                   support=layout.support("P1")),
    ]  # fmt: skip
    if not rest:
        return layout, feas, [], None
    return layout, feas, posed(JOINT, at, "rest"), _objective(aug, layout)


def _objective(aug: Augmented, layout: Layout) -> np.ndarray:
    """Step 5's objective ``min sy^2 sum_i rho_i + tau``."""
    c = np.zeros(layout.size)
    # rho_i enters as rho_i Cbar^T Cbar: outputs sy times larger (mm for m) give the same observer at rho_i / sy^2,
    # and an unweighted sum rho_i + tau then weighs the gains sy^2 times less (a slow 4-state plant in mm needed a
    # sample time of 3.6e-4 s where in m it runs at 1 s); weighted by sy^2 the objective, and the design, do not
    # depend on the outputs' units (sy = 1 for every built-in plant: their designs are unchanged)
    c[layout.index("rho")] = output_scale(aug) ** 2
    c[layout.index("tau")] = 1.0
    return c


class _Step5:
    """Step 5 built once per design: the LMIs, one conic solve, and deterministic decisions in alpha.

    The one conic solve is the feasibility of (46) with the normalisation at ``alpha = 0``. Every
    further question "is (46) feasible at alpha?" is answered by :func:`~fte_casadi.design.core._barrier.phase1`
    (a barrier method in numpy) on a growing subset of the rules (:func:`~fte_casadi.design.core._barrier.phase1_active`:
    a few rules decide; the answer is the same fact as on all of them), started from the last point found
    feasible: its answer does
    not depend on the solver, so the default alpha (and hence the design) is the same with
    Clarabel and SCS. (46) is monotone in alpha (``2 alpha Pt >= 0``): a point feasible at some
    alpha is a strictly feasible start for the centring at every smaller alpha.
    """

    def __init__(self, aug, params, X, K, T, solver, joint: bool = False):
        self.aug, self.T, self.solver, self.kappa = aug, T, solver, _kappa(params)
        self.params, self.X, self.K, self.tau = params, X, K, time_scale(aug)
        self.joint = joint  # Theorem 1's (29) with P29 an unknown, instead of (46) at step 3's P
        self.layout, feas, rest, self.c = _step5_problem(aug, params, X, K, T, joint=joint)
        r = aug.r
        self.feas = self.feas0 = ConicProblem(self.layout, [L.at(2 * MARGIN) for L in feas])
        self.soft = [L.at(MARGIN) for L in feas[:r]]  # (46) per rule: depends on alpha
        self.fixed = [L.at(MARGIN) for L in feas[r:]]  # the normalisation of Pt
        self.centring = [L.at(MARGIN) for L in feas + rest]
        # phase 1 needs bounded gains: rho_i <= RHO_CAP (far above any design's; see module docstring)
        self.rho_cap = RHO_CAP * self.kappa * max(np.linalg.norm(T @ A, 2) for A in aug.Abar) / max(
            np.linalg.svd(aug.Cbar, compute_uv=False)[-1] ** 2, 1e-300)  # fmt: skip
        ir = self.layout.index("rho")
        self.caps = []
        for i in range(r):
            F = np.zeros((self.layout.size, 1, 1))
            F[ir.start + i, 0, 0] = 1.0
            self.caps.append(AffineLMI(f"rho_{i + 1} <= cap", np.array([[-self.rho_cap]]), F))
        self.notes: list[str] = []
        self.points: dict[float, np.ndarray] = {}  # alpha -> a strictly feasible point there
        self.newton = 0
        self.decisions = 0
        self.active: list[int] = []  # the rules that decided the last phase 1 (phase1_active)
        self.bound = None  # the closed-loop bound's term of the objective (bound_objective), when asked for

    @property
    def solves(self) -> int:
        return self.feas.solves

    @property
    def seconds(self) -> float:
        return self.feas.seconds

    def _conic(self) -> SolveResult:
        """The feasibility solve of (46) with the normalisation at alpha = 0, posed in the time ``t / tau``
        (:func:`~fte_casadi.design._augment.time_scaled`: ``Pbar' = Pbar / tau``, ``P' = P / tau``, the same
        Q_i) and mapped back exactly to the unknowns of the unscaled problem. Only the starting point
        comes from here; the centring runs on the unscaled LMIs."""
        if self.feas.heavy and self.feas.layout is self.layout:
            res = self._numpy()
            if res is not None:
                return res
        if self.tau == 1.0:
            return self.feas.solve(self.solver, 0.0)
        tau = self.tau
        if self.feas.layout is self.layout:  # not built in the scaled time yet
            aug_s = time_scaled(self.aug, tau)
            params_s = dict(self.params, sigma=self.params["sigma"] * tau**2)
            layout_s, feas_s, _, _ = _step5_problem(aug_s, params_s, tau * self.X, self.K, self.T, rest=False,
                                                    joint=self.joint)  # fmt: skip
            self.feas = ConicProblem(layout_s, [L.at(2 * MARGIN) for L in feas_s])
        layout_s = self.feas.layout
        res = self.feas.solve(self.solver, 0.0)
        if res.v is None or not np.all(np.isfinite(res.v)):
            return res
        u = layout_s.unpack(res.v)
        # (29) of the scaled data at (P1t, Pt, tau s, tau rho) is tau times (29) at (P1t, Pt, s, rho): the same map
        loop = {"P1": u["P1"]} if self.joint else {}
        v = self.layout.pack(Pt=u["Pt"], s=u["s"] / tau, rho=u["rho"] / tau, tau=0.0, **loop)
        return replace(res, v=v)

    def _numpy(self) -> SolveResult | None:
        """The feasibility of (46) at alpha = 0 by phase 1 in numpy (:func:`~._barrier.numpy_first`): (46) per rule
        soft, the normalisation and the gain caps hard, from ``Pt = sqrt(kappa) I``, ``s = rho_i = 1``."""
        loop = {"P1": np.sqrt(self.kappa) * np.eye(self.aug.n)} if self.joint else {}
        v0 = self.layout.pack(
            Pt=np.sqrt(self.kappa) * np.eye(self.aug.nbar), s=1.0, rho=np.ones(self.aug.r), **loop
        )
        res = numpy_first(self.feas0, self.aug.r, v0, self.caps)
        if res is not None and self.feas0 is not self.feas:  # the time-scaled problem keeps the account
            self.feas.seconds += res.seconds
            self.feas.notes.append(self.feas0.notes[-1])
        return res

    def first(self) -> SolveResult:
        """The conic solve at alpha = 0; its point (gains clipped to the cap) starts everything else.

        Where the solver fails numerically, or its point cannot be repaired into a strictly feasible one,
        phase 1 in numpy decides instead (a point, or a proof that none exists under the gain caps); failing
        that, the other solver is tried here: only this point comes from a solver (the decisions and the
        centring run in numpy), so the design does not change, and steps 1-3 are not run again."""
        res = self._conic()
        if not self._take(res):
            numpy_res = self._numpy()
            if numpy_res is not None:
                self.notes.append(f"step 5: {self.solver}'s feasibility solve gave no usable point ({shorten(res.status, 120)}); "
                                  f"phase 1 in numpy decided")  # fmt: skip
                res = replace(numpy_res, seconds=res.seconds + numpy_res.seconds, warned=res.warned)
                self._take(res)
        if not self.points and res.failed:
            other = "SCS" if self.solver == "CLARABEL" else "CLARABEL"
            first, self.solver = res, other
            res = self._conic()
            res = replace(res, seconds=first.seconds + res.seconds, warned=first.warned + res.warned)
            self.notes.append(
                f"step 5: {'SCS' if other == 'CLARABEL' else 'CLARABEL'} failed numerically on the feasibility solve "
                f"({shorten(first.status, 120)}, also on rescaled data); {other}'s point ({res.status}) starts the centring"
            )
            self._take(res)
        return res

    def _take(self, res: SolveResult) -> bool:
        """Record a strictly feasible start from ``res`` (its gains clipped to the cap); False when there is none."""
        if res.v is None or not np.all(np.isfinite(res.v)):
            return False
        v = res.v.copy()
        ir = self.layout.index("rho")
        v[ir] = np.minimum(v[ir], 0.5 * self.rho_cap)
        start = _start(
            replace(res, v=v), self.layout, "Pt", self.soft, self.fixed + self.caps, self.notes, self.kappa
        )
        if start is None:
            return False
        self.points[self.reach(start)] = start
        return True

    def reach(self, v: np.ndarray) -> float:
        """The largest alpha at which the point ``v`` itself satisfies every (46): with
        ``-F(v) = L L^T`` and the decay term ``alpha G(v)``, ``1 / lambda_max(L^-1 G(v) L^-T)`` (exact)."""
        best = np.inf
        for Lm in self.soft:
            Lc = np.linalg.cholesky(-Lm.value(v, 0.0))
            G = np.tensordot(v, Lm.G, 1)
            Li = np.linalg.inv(Lc)
            lam = float(np.linalg.eigvalsh(Li @ G @ Li.T)[-1])
            if lam > 0:
                best = min(best, 1.0 / lam)
        return best * (1 - 1e-9)

    def feasible(self, alpha: float) -> bool:
        """Is (46) with ``I <= Pt <= kappa I`` strictly feasible at ``alpha``? (phase 1 in numpy)

        A known point whose reach covers ``alpha`` answers without a new phase 1. The answer is a
        fact about the LMIs, so the sequence of questions the bisection asks, and hence the
        default alpha, does not depend on which point happened to answer it."""
        if any(r >= alpha for r in self.points):
            return True
        below = [a for a in self.points if a <= alpha]
        if not below:
            return False
        try:
            v, self.active = phase1_active([L.at(alpha) for L in self.soft], self.fixed, self.points[max(below)],
                                           self.active, tied=[[cap] for cap in self.caps])  # fmt: skip
        except CentringError as exc:
            self.notes.append(f"step 5: phase 1 at alpha = {alpha:.4g} failed ({exc}); counted as infeasible")
            return False
        self.decisions += 1
        if v is None:
            return False
        self.points[max(alpha, self.reach(v))] = v
        return True

    def start(self, alpha: float) -> np.ndarray | None:
        """A strictly feasible point for the centring at ``alpha`` (from a feasible alpha' >= alpha)."""
        above = [a for a in self.points if a >= alpha]
        if not above:
            return None
        v = self.points[min(above)].copy()
        Pt = self.layout.unpack(v)["Pt"]
        aug, T, Cp = self.aug, self.T, np.linalg.pinv(self.aug.Cbar)
        E = [sliding_mismatch(aug, T, Pt, aug.Js.T @ T.T @ Pt @ Cp)] + [
            diffusion_coupling(aug, i, T, Pt) for i in range(aug.r)
        ]
        v[self.layout.index("tau")] = 2.0 * max(np.linalg.norm(e, 2) for e in E) + 1.0
        return v

    def design(self, alpha: float) -> dict | None:
        """The centred design at ``alpha``, or None when (46) is not known feasible there."""
        if self.start(alpha) is None and not self.feasible(alpha):
            return None
        v0 = self.start(alpha)
        try:
            cen = centre([L.at(alpha) for L in self.centring], self.c, v0, eta=ETA)
        except CentringError as exc:
            self.notes.append(f"step 5: centring failed at alpha = {alpha:.4g} ({exc})")
            return None
        self.newton += cen.newton_steps
        v, info = cen.v, None
        if self.bound is not None:
            got = self.bound.improve([L.at(alpha) for L in self.centring], self.c, v, ETA)
            if got is not None:
                v, info = got[0][: self.layout.size], got[1]
                self.newton += info["newton_steps"]
        u = self.layout.unpack(v)
        aug, T, s = self.aug, self.T, u["s"]
        Pbar = u["Pt"] / s
        Q = [u["rho"][i] * aug.Cbar.T / (2 * s) for i in range(aug.r)]
        N = aug.Js.T @ T.T @ Pbar @ np.linalg.pinv(aug.Cbar)
        L1 = [np.linalg.solve(Pbar, Qi) for Qi in Q]
        R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
        return dict(Pbar=Pbar, Q=Q, N=N, theta=float((u["tau"] / s) ** 2), R=R, ts_max=ts_max(R),
                    ts_cert=lyapunov_ts_max(R, Pbar), bound=info, P29=u["P1"] / s if self.joint else None)  # fmt: skip


def step5(aug: Augmented, params: dict, X, K, T, solver: str, *, alpha: float | None = None,
          sample_time: float | None = None, bound_view=None, alpha_is_default: bool = False,
          joint: bool = False) -> Step5:  # fmt: skip
    """Step 5 (conditioned): Pbar, Q_i, N, theta from (46), (55), (64) with the observer decay rate.

    With ``params["bound_weight"] > 0``, the closed loop's fault-error bound is a term of the objective
    (:mod:`fte_casadi.design.core._bound_objective`; ``bound_view`` the closed loop's data without R).
    ``alpha_is_default``: ``alpha`` is the plant's recorded default (``fte tune``'s), not the user's: like the
    rate found by default, it is lowered when the sample time needs it. ``joint``: Theorem 1's (29) in place of
    (46), the loop's block of V (``P29``) an unknown as well (:func:`_step5_joint`; no bound term)."""
    prob = _Step5(aug, params, X, K, T, solver, joint=joint)
    lmi = "(29)" if joint else "(46)"
    if joint:
        why_not = (
            "the fault-error bound is not in the objective of (29)" if params.get("bound_weight") else ""
        )
    else:
        prob.bound, why_not = bound_term(
            prob.layout, aug, T, np.linalg.inv(X), bound_view, params.get("bound_weight")
        )
    if why_not:
        prob.notes.append(f"step 5: {why_not}")
    res0 = prob.first()
    if not prob.points:
        l2 = aug.Mbar[0].shape[1]
        if joint:
            names = {aug.n + aug.ld + aug.nbar + l2: [("x", aug.n), ("d", aug.ld), ("e", aug.nbar)]
                     + ([("d2", l2)] if l2 else [])}  # fmt: skip
            hint = "the loop's own decay must dominate its coupling with the observer and the diffusion"
        else:
            names = {aug.n + aug.nbar + l2: [("x", aug.n), ("e", aug.nbar)] + ([("d2", l2)] if l2 else [])}
            hint = (
                "its -sigma P^2 block must dominate the observer's coupling with the loop and the diffusion"
            )
        raise _fail(f"LMI {lmi} with cond(Pbar) <= {prob.kappa:g}", res0, solver, hint,
                    worst_block(prob.feas.lmis, names), lmi=lmi.strip("()"))  # fmt: skip
    n = aug.n
    decays = [
        -float(np.max(np.linalg.eigvals(aug.Abar[i][:n, :n] + aug.Bbar[i][:n] @ K).real))
        for i in range(aug.r)
    ]
    start = max(min(decays), 1e-6)
    observer: dict = {"sample_time": sample_time}
    if alpha is None:
        lo, hi = alpha_max(prob, start)
        a = ALPHA_FRACTION * lo if np.isfinite(hi) else lo
        observer.update(alpha_max=lo, alpha_max_upper=hi)
        why = (f"{ALPHA_FRACTION:g} x the largest decay rate for which {lmi} is feasible with cond(Pbar) <= {prob.kappa:g} "
               f"(alpha_max in [{lo:.4g}, {hi:.4g}], by bisection)")  # fmt: skip
    else:
        a = float(alpha)
        why = "the plant's design defaults (fte tune's choice)" if alpha_is_default else "set by the user"
    pt = prob.design(a)
    if (
        pt is None and alpha_is_default
    ):  # the plant's rate, tuned at its own parameters, is not feasible at these
        lo, hi = alpha_max(prob, start)
        observer.update(alpha_max=lo, alpha_max_upper=hi)
        a = ALPHA_FRACTION * lo if np.isfinite(hi) else lo
        why = (f"the plant's default alpha = {float(alpha):g} is infeasible at these parameters: {ALPHA_FRACTION:g} x the "
               f"largest decay rate for which {lmi} is feasible with cond(Pbar) <= {prob.kappa:g} (alpha_max in "
               f"[{lo:.4g}, {hi:.4g}], by bisection)")  # fmt: skip
        pt = prob.design(a)
    elif pt is None and alpha is not None:
        lo, hi = alpha_max(prob, start)
        raise InfeasibleDesignError(
            f"step 5 at the observer decay rate alpha = {a:g} is infeasible: the largest alpha for which {lmi} is "
            f"feasible with cond(Pbar) <= {prob.kappa:g} is about {lo:.4g}; lower alpha to <= "
            f"{nice_floor(ALPHA_FRACTION * lo):g} (or leave it unset for the default)",
            kind=Refused.DECAY_RATE,
            lmi="46",
            numbers={"alpha": a, "alpha_max": lo},
        )
    if pt is None and (
        alpha is None or alpha_is_default
    ):  # the rate is the tool's choice: a slower one is inside
        for f in (0.5, 0.25):
            pt = prob.design(f * a)
            if pt is not None:
                why = (f"{f:g} x the rate first chosen ({a:.4g}), at which the centring failed ({prob.notes[-1]}); "
                       + why)  # fmt: skip
                a *= f
                break
    if pt is None:
        raise SolverFailedError(
            f"step 5: no centred design found ({'; '.join(prob.notes[-2:])})", solver_independent=True
        )
    if (
        (alpha is None or alpha_is_default)
        and sample_time is not None
        and pt["ts_cert"] < TS_FACTOR * sample_time
    ):
        a0 = a
        a, pt, why = cap_for_sample_time(prob, a, pt, why, sample_time)
        if (
            a < a0
        ):  # the sample time binds the rate (where no lower rate widens the margin, a is kept: it does not)
            observer["alpha_before_sample_time"] = a0
    observer.update(alpha=a, why=why)  # ts_max is the certificate's (checks.ts_max)
    if pt["bound"] is not None:
        b = pt["bound"]  # its weight is params.bound_weight
        observer.update(bound_objective_unweighted=b["before"], bound_objective=b["after"])
        prob.notes.append(
            f"step 5: the closed-loop fault-error bound (block-diagonal P = diag(P1, Pbar), the smallest sum of the "
            f"squared channel gains at the observer) is in the objective with weight {b['weight']:g}: "
            f"{b['before']:.4g} without it, {b['after']:.4g} with it"
        )
    elif prob.bound is not None:
        prob.notes += [f"step 5: {x}" for x in prob.bound.notes[-1:]]
    notes = [
        ("step 5: Theorem 1's (29) in place of (46): V = x^T P29 x + e^T Pbar e at step 3's K, P29 = P1t/s an unknown "
         "as well (no sigma, no gamma1); " if joint else "step 5: ")
        + f"Q_i = rho_i Cbar^T / 2 (Finsler), N = J1^T T^T Pbar Cbar^+, Pbar = Pt/s with I <= Pt <= {prob.kappa:g} I, "
        f"min sum rho_i + tau; observer decay rate alpha = {a:.4g} ({why}); {prob.solves} conic solve "
        f"({res0.status}" + (", on rescaled data" if res0.rescaled else "") + f") at alpha = 0, then "
        f"{prob.decisions} phase-1 decisions and {prob.newton} centring steps in numpy"
    ] + prob.notes + [f"step 5: {solver} warned: {w!r}" for w in res0.warned] + [f"step 5: {x}" for x in prob.feas.notes]  # fmt: skip
    return Step5(
        pt["Pbar"],
        pt["Q"],
        pt["N"],
        pt["theta"],
        a,
        res0.status,
        prob.solves,
        prob.seconds,
        observer,
        notes,
        pt["bound"],
        prob.kappa,
        pt["P29"],
    )
