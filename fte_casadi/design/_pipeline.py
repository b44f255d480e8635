"""The design as a pipeline of records: structure (augment, H, assumptions) -> step 3 -> step 5 -> certificate
-> bounds, each stage a function of the records before it.

No stage retries or searches: a stage that fails raises (:class:`~fte_casadi.errors.InfeasibleDesignError`,
:class:`~fte_casadi.design.core._conditioned.SolverFailedError`), and :func:`fte_casadi.design.design` decides
what to try next or what to say (:mod:`fte_casadi.design.diagnose`).
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import hashlib
import time
from dataclasses import dataclass
from textwrap import shorten
from types import SimpleNamespace

import numpy as np

from .._progress import note
from ..errors import AssumptionError, FteError, InfeasibleDesignError, Refusal, Refused
from ..model import plant_fingerprint
from ..ts import TSModel, scheduling_from_measurements
from ..verdicts import SATURATES_EARLY
from ._augment import Augmented, augment
from ._model_form import holding_input, missed_motion
from ._options import DesignOptions, Resolved
from ._parts import Dims, Observer, Params
from ._recertify import certify, unsaturated
from ._record import Design
from ._remark5 import explain_causes, with_remark5
from ._remark5 import fallback as remark5_fallback
from ._remark5 import record as remark5_record
from ._uio import accepted_names, check_assumptions, enforce, uio_gain
from .core import _conditioned as conditioned
from .core import _paper as paper
from .core import _step5
from .core._certify import failed
from .core._diagnose import reach_max
from .core._lmis import LMIS, loop_decay

__all__ = ["structure", "step3", "step5"]

PAPER_NOTE = "paper variant: problem as printed (with the corrections of docs/method.md); expect an ill-conditioned Pbar"


@dataclass(frozen=True)
class Structure:
    """The augmented system of a design, its unknown-input gain ``H`` (``T = I - H Cbar``), the assumption
    checks of Section 3 (``checks``), Remark 5's record (``r5doc``, empty where not used) and the stage's notes."""

    aug: Augmented
    H: np.ndarray
    T: np.ndarray
    checks: list
    r5doc: dict
    notes: tuple

    @property
    def assumptions_hold(self) -> bool:
        return all(c.holds for c in self.checks)


def structure(ts: TSModel, options: DesignOptions, resolved: Resolved) -> Structure:
    """Augment ``ts``, find H and T, check the assumptions (with Remark 5's fallback where H cannot decouple
    the unknown inputs); raises :class:`~fte_casadi.errors.AssumptionError` on a failed assumption that is
    not accepted."""
    notes: list[str] = []
    aug = augment(ts.local_models, ts.C, ts.Df)
    if any(lm.has_diffusion_extension for lm in ts.local_models):
        notes.append(
            "Theorem 5: faults/inputs/d2 in the diffusion, LMIs (78)-(81) (keys 45/46/55/64 hold the same values)"
        )
    H, T = uio_gain(aug)
    checks_a = check_assumptions(aug, T)
    r5 = remark5_fallback(aug, checks_a, options.remark5)
    if r5 is not None:  # Remark 5: H decouples what it can, the sliding term attenuates the rest
        H, T, aug = r5.H, r5.T, with_remark5(aug, r5)
        checks_a = check_assumptions(aug, T, remark5=r5)
    checks_a = explain_causes(
        _named(checks_a, aug, ts, options.accept_assumptions), aug, ts.plant, options.remark5
    )
    try:
        notes += enforce(checks_a, options.accept_assumptions)
    except AssumptionError as exc:
        raise AssumptionError(str(exc) + _scaling_note(ts)) from None
    r5doc = (
        {}
        if r5 is None
        else remark5_record(r5, options.d_bound, resolved.params, ts.plant.unknown_input_names)
    )
    notes += [r5doc["message"]] if r5doc else []
    return Structure(aug, H, T, checks_a, r5doc, tuple(notes))


def paper_steps(st: Structure, resolved: Resolved, solver: str):
    """Steps 3 and 5 as printed (:mod:`~fte_casadi.design.core._paper`): ``(step3, K, step5)``."""
    s3, K = paper.step3(st.aug, resolved.params, solver)
    s5 = paper.step5(st.aug, resolved.params, s3.X, K, st.T, solver)
    return s3, K, s5


#: within :func:`step3_reused`, step 3's results by their inputs (None: outside, every step 3 is made)
_STEP3: contextvars.ContextVar[dict | None] = contextvars.ContextVar("fte_step3", default=None)


@contextlib.contextmanager
def step3_reused():
    """Designs made inside share step 3 where its inputs are equal (the augmented system, the parameters, the
    solver and the loop's rate): a design made again at another observer decay rate makes step 3 once. Step 3
    does not depend on the observer's rate, so the designs are those made apart."""
    token = _STEP3.set({})
    try:
        yield
    finally:
        _STEP3.reset(token)


def _step3_key(st: Structure, resolved: Resolved, solver: str) -> str:
    """What step 3 is a function of: the solver, the loop's rate, the parameters and every field of the augmented
    system (each array by its shape and bytes)."""
    h = hashlib.sha256(repr((solver, resolved.beta, sorted(resolved.params.items()))).encode())
    for f in dataclasses.fields(st.aug):
        v = getattr(st.aug, f.name)
        for a in v if isinstance(v, tuple) else (v,):
            if isinstance(a, np.ndarray):
                h.update(repr(a.shape).encode() + np.ascontiguousarray(a, dtype=float).tobytes())
            else:
                h.update(repr(a).encode())
    return h.hexdigest()


def step3(st: Structure, resolved: Resolved, solver: str, *, search: bool = True) -> conditioned.Step3:
    """Step 3, conditioned: the common gain K from (45), the closed loop asked to decay at ``options.beta`` (None:
    the default of :func:`~fte_casadi.design.core._decay.loop_decay_target`); made once per inputs inside
    :func:`step3_reused`.

    Where (45) is infeasible under the default bound on cond(X') and no kappa was given, the larger bounds of
    :data:`KAPPA_LADDER` are tried (kappa searched, as for the observer), and the first under which it is feasible
    is kept, said so; the observer is then designed under it too (one kappa, :func:`params_of`). Only with
    ``search`` (the design's ``diagnose``: not in the parameter search's trials or ``--explore``'s grid, as for
    step 5's bound where (46) is infeasible: there it doubled a refusal's time). The bound is a
    matter of units, not of the plant: a state measured in units far from its range (a levitation's gap in m,
    1e-3 wide, beside its current in A) needs cond(X) ~ 1e7 for the same Lyapunov function."""
    try:
        return _step3_once(st, resolved, solver)
    except InfeasibleDesignError as exc:
        if (
            not search
            or "kappa" in resolved.params
            or exc.refusal.lmi != "45"
            or not _within_sigma_max(st, resolved, solver)
        ):
            raise
        first = exc

    def under(kappa: float):
        try:
            return _step3_once(
                st, dataclasses.replace(resolved, params=dict(resolved.params, kappa=kappa)), solver
            )
        except InfeasibleDesignError:
            return None

    found = on_ladder(under)
    if found is not None:
        kappa, s3 = found
        s3.notes.insert(0, f"step 3: kappa = {kappa:g}: LMI (45) is infeasible with cond(X') <= {conditioned.KAPPA:g} "
                           f"(the bound binds), feasible under {kappa:g}, the smallest of {KAPPA_LADDER} that is")  # fmt: skip
        return s3
    r = first.refusal
    raise InfeasibleDesignError(dataclasses.replace(
        r, statement=f"{r.statement.rstrip('.')}; and with cond(X') <= {KAPPA_LADDER[-1]:g} too (the bound is not what "
                     "binds)", bounded=False, numbers=dict(r.numbers, kappa=KAPPA_LADDER[-1])), first.result) from None  # fmt: skip


def on_ladder(under):
    """``(kappa, under(kappa))`` for the smallest bound of :data:`KAPPA_LADDER` above the default under which
    ``under`` gives a result (not None), or None. The ladder's top first: where it gives none there either (the
    common case: the cap is not what binds), one call decides it."""
    top = under(KAPPA_LADDER[-1])
    if top is None:
        return None
    return next(
        (k, s) for k in KAPPA_LADDER[1:] if (s := top if k == KAPPA_LADDER[-1] else under(k)) is not None
    )


def _within_sigma_max(st: Structure, resolved: Resolved, solver: str) -> bool:
    """Does (45) allow this sigma without a bound on cond(X) (:func:`~fte_casadi.design.core._diagnose.sigma_max`,
    one conic solve, remembered)? Where it does not, no kappa helps."""
    from .core._diagnose import sigma_max

    p = resolved.params
    smax, _ = sigma_max(st.aug, p["gamma"], p["gamma1"], solver)
    return smax is not None and float(p["sigma"]) < smax


def _step3_once(st: Structure, resolved: Resolved, solver: str) -> conditioned.Step3:
    memo = _STEP3.get()
    if memo is None:
        return conditioned.step3(st.aug, resolved.params, solver, beta=resolved.beta)
    key = _step3_key(st, resolved, solver)
    if key not in memo:
        memo[key] = conditioned.step3(st.aug, resolved.params, solver, beta=resolved.beta)
    s3 = memo[key]
    return dataclasses.replace(s3, notes=list(s3.notes))


def params_of(resolved: Resolved, s3) -> dict:
    """The parameters the observer is designed with after step 3: ``resolved.params`` with step 3's kappa where
    :func:`step3` raised it (one bound on cond(X') and cond(Pbar) per design, as ``--kappa`` sets both)."""
    kappa = getattr(s3, "kappa", conditioned.KAPPA)
    if "kappa" in resolved.params or kappa == conditioned.KAPPA:
        return resolved.params
    return dict(resolved.params, kappa=float(kappa))


#: the bounds on cond(Pbar) tried, in order, for an observer too slow for the fault windows it must settle in
KAPPA_LADDER = (1e4, 1e5, 1e6, 1e7, 1e8)
#: observer time constants that must fit in the shortest fault window (as the verdict ``slow observer``)
SETTLE = 3.0


def slowest_rate(st: Structure, s5) -> float:
    """``min_i -max Re eig(R_i)`` of step 5's observer: its slowest decay rate (negative: a mode grows)."""
    aug = st.aug
    return min(
        -float(
            np.max(np.linalg.eigvals(st.T @ aug.Abar[i] - np.linalg.solve(s5.Pbar, s5.Q[i]) @ aug.Cbar).real)
        )
        for i in range(aug.r)
    )


def step5(ts: TSModel, st: Structure, options: DesignOptions, resolved: Resolved, s3, *,
          joint: bool = False) -> conditioned.Step5:  # fmt: skip
    """Step 5, conditioned: Pbar, Q_i, N, theta from (46), (55), (64) at the resolved decay rate (a rate from
    the plant's defaults gives way, as a default, where it is infeasible or the sample time needs it).

    ``joint``: Theorem 1's (29) in place of (46) (the closed loop's own certificate at step 3's K, with the loop's
    block of V an unknown), with the same search of kappa and the same settling window; :func:`loop_then_observer`
    asks for it only where (46) gives no observer at any loop it tries.

    With ``options.settle_window`` (the scenario's shortest fault window), the observer must settle in it:
    :data:`SETTLE` of its slowest time constants at most that long. Where the default decay rate is too slow for
    that at the bound kappa on cond(Pbar), the larger bounds of :data:`KAPPA_LADDER` are tried (kappa searched,
    not fixed), and the first that fits is kept; where none does, the design is refused naming what binds
    (:func:`_too_slow`). Where (46) is infeasible under the bound (and ``options.diagnose``: not in the parameter
    search's trials), the larger bounds are tried too, and a refusal says the cap was not what binds. A decay
    rate or a kappa the user gave is kept as given (then only a warning)."""
    K = [s3.K] * st.aug.r
    view = _closed_loop_view(ts, st.T, K, st.r5doc) if resolved.params.get("bound_weight") else None
    window = options.settle_window
    settle = bool(window) and resolved.alpha_source != "user" and "kappa" not in resolved.params
    need = SETTLE / float(window) if settle else 0.0

    base = params_of(resolved, s3)

    def at(params):
        return _step5.step5(st.aug, params, s3.X, s3.K, st.T, options.solver, alpha=resolved.alpha,
                                 sample_time=options.sample_time, bound_view=view,
                                 alpha_is_default=resolved.alpha_source == "plant", joint=joint)  # fmt: skip

    try:
        s5 = at(base)
    except InfeasibleDesignError as exc:
        if (
            not options.diagnose
            or "kappa" in resolved.params
            or not (exc.refusal.lmi in ("46", "29") and exc.refusal.bounded)
        ):
            raise
        s5 = _kappa_for_46(at, base, exc)
    if not settle:
        return s5
    rate = slowest_rate(st, s5)
    if rate >= need:
        return s5
    tried = [(s5.kappa, rate, s5)]
    for kappa in (k for k in KAPPA_LADDER if k > s5.kappa):
        try:
            s5k = at(dict(base, kappa=kappa))
        except FteError as exc:
            tried.append((kappa, None, exc))
            continue
        rate = slowest_rate(st, s5k)
        tried.append((kappa, rate, s5k))
        if rate >= need:
            s5k.notes.insert(0, f"step 5: kappa = {kappa:g}, the smallest bound on cond(Pbar) of {KAPPA_LADDER} whose "
                                f"observer settles within the shortest fault window {window:g} ({SETTLE:g} time constants "
                                f"{SETTLE / rate:.3g}; at kappa = {s5.kappa:g}: {SETTLE / tried[0][1]:.3g})")  # fmt: skip
            return s5k
    raise InfeasibleDesignError(_too_slow(ts, st, options, resolved, s3, window, need, tried, joint))


def _kappa_for_46(at, params: dict, exc: InfeasibleDesignError):
    """Step 5 under the larger bounds of :data:`KAPPA_LADDER` where (46) is infeasible under the default one: the
    first feasible, said so; else ``exc``, saying that no bound up to the ladder's end made it feasible."""
    base = float(params.get("kappa", conditioned.KAPPA))
    for kappa in (k for k in KAPPA_LADDER if k > base):
        try:
            s5 = at(dict(params, kappa=kappa))
        except InfeasibleDesignError:
            continue
        s5.notes.insert(0, f"step 5: kappa = {kappa:g}: ({exc.refusal.lmi}) is infeasible with cond(Pbar) <= {base:g} (the bound "
                           f"binds), feasible under {kappa:g}, the smallest of {KAPPA_LADDER} that is")  # fmt: skip
        return s5
    r = exc.refusal
    statement = f"{r.statement.rstrip('.')}; and with cond(Pbar) <= {KAPPA_LADDER[-1]:g} too (the bound is not what binds)"
    raise InfeasibleDesignError(
        dataclasses.replace(
            r, statement=statement, bounded=False, numbers=dict(r.numbers, kappa=KAPPA_LADDER[-1])
        )
    ) from None


def loop_then_observer(ts: TSModel, st: Structure, options: DesignOptions, resolved: Resolved, s3):
    """``(s3, s5)``: step 5 at step 3's loop (:func:`_loops`), by (46); where (46) gives no observer at any loop tried
    (infeasible, too slow for the fault windows, or not at the sample time), the same by Theorem 1's (29)
    (:func:`step5` with ``joint``), which (45)-(46) imply but which also holds where they do not (docs/method.md).
    A design (46) certifies is therefore the one it always was; a refusal by both names both."""
    try:
        return _loops(ts, st, options, resolved, s3, joint=False)
    except InfeasibleDesignError as exc:
        first = exc
    note("step 5: (46) gave no observer; Theorem 1's (29) at step 3's K")
    try:
        s3j, s5j = _loops(ts, st, options, resolved, s3, joint=True)
    except (InfeasibleDesignError, conditioned.SolverFailedError) as jexc:
        also = (
            f"; and Theorem 1's (29) at step 3's K fails too ({shorten(str(jexc), 800, placeholder=' ...')})"
        )
        raise InfeasibleDesignError(
            dataclasses.replace(first.refusal, statement=first.refusal.statement.rstrip(".") + also),
            first.result,
        ) from None
    s5j.notes.insert(0, f"step 5: certified by Theorem 1's (29): (45)-(46) give no observer ({shorten(str(first), 200, placeholder=' ...')}); "
                        "(29) at step 3's K, with the loop's block of V an unknown, does")  # fmt: skip
    return s3j, s5j


def _loops(ts: TSModel, st: Structure, options: DesignOptions, resolved: Resolved, s3, joint: bool):
    """``(s3, s5)``: step 5 at step 3's loop, by (46) or, with ``joint``, by (29). A faster loop asks more of the observer ((46)'s ``-sigma P^2`` block
    must dominate its coupling with the loop, ``P B K``): where the loop's DEFAULT rate (posed in step 3) asks an
    observer that step 5 cannot give (infeasible, too slow for the fault windows, or not at the sample time),
    the loop is designed again at the default's lower rate, then with the smallest gain of (45) alone, and the
    first whose observer step 5 gives is kept, said so. A rate the user gave is kept (its failure raised)."""
    try:
        return s3, step5(ts, st, options, resolved, s3, joint=joint)
    except (InfeasibleDesignError, conditioned.SolverFailedError) as exc:
        if resolved.beta is not None or not getattr(s3, "posed", False):
            raise
        first = exc
    because = (f"the loop at {s3.beta:.4g} asks an observer that step 5 cannot give ("
               f"{shorten(str(first), 240, placeholder=' ...')})")  # fmt: skip
    for b in _lower_rates(s3):
        s3b = _loop_at(st, resolved, s3, options.solver, b, because)
        try:
            s5 = step5(ts, st, options, resolved, s3b, joint=joint)
        except (InfeasibleDesignError, conditioned.SolverFailedError):
            continue
        return s3b, s5
    raise first


def _lower_rates(s3) -> tuple:
    """The loop's rates tried below its DEFAULT one: the default's lower rate (where it has one), then none."""
    return (s3.low, 0.0) if s3.low > 0 else (0.0,)


def _loop_at(st: Structure, resolved: Resolved, s3, solver: str, b: float, because: str):
    """Step 3 again at the lower rate ``b`` (0: the smallest gain of (45) alone), its note saying ``because``; with
    no rate asked, the rate it decays at for any blending is recorded (the LMI "decay" certifies it)."""
    what = f"at the lower rate {b:.4g}" if b > 0 else "with the smallest gain (45) allows (no rate asked)"
    s3b = conditioned.step3(st.aug, params_of(resolved, s3), solver, beta=b,
                            why=f"{s3.beta_why}; {because}, so the loop is designed {what}")  # fmt: skip
    if b == 0.0:
        s3b.beta = float(loop_decay(st.aug, s3b.X, [s3b.K])) * (1 - 4 * conditioned.MARGIN)
    return s3b


def _too_slow(
    ts, st, options, resolved, s3, window: float, need: float, tried: list, joint: bool = False
) -> Refusal:
    """Why no observer of the kappa ladder settles within ``window``: the limit that binds, with its number."""
    rates = [(k, r) for k, r, _ in tried if r is not None]
    best_k, best_r = max(rates, key=lambda t: t[1]) if rates else (None, None)
    best = next((s for k, r, s in tried if k == best_k), None)
    head = (f"no certified observer settles within the scenario's shortest fault window {window:g}: {SETTLE:g} time "
            f"constants need a decay rate of {need:.3g}, and the fastest found decays at "
            + (f"{best_r:.3g} (kappa = {best_k:g}; " + ", ".join(f"{r:.3g} at kappa = {k:g}" for k, r in rates) + ")"
               if best_r is not None else "none (every kappa tried was refused)"))  # fmt: skip
    numbers = {"window": window, "rate_needed": need, **({"rate": best_r, "kappa": best_k} if rates else {})}
    a0 = best.observer.get("alpha_before_sample_time") if best is not None else None
    # the sample time lowered the rate; it binds only where the rate (46) allowed before that reaches the need
    shortened = ("" if a0 is None else
                 f"; the sample time {options.sample_time:g} lowered the rate further, from {a0:.3g}, so a shorter one "
                 f"gives at most that")  # fmt: skip
    if a0 is not None and a0 >= need:
        limit = (f"What binds is the sample time {options.sample_time:g}: the decay rate was lowered from {a0:.3g} so "
                 "that the discrete step z+ = z + Ts (...) is proven stable; a shorter sample time allows a faster "
                 "observer")  # fmt: skip
        lmi, bounded = None, False
    elif len(rates) >= 2 and rates[-1][1] > 1.1 * rates[-2][1]:
        limit = (f"What binds is kappa, the bound on cond(Pbar): the rate still grows with it ({rates[-2][1]:.3g} at "
                 f"{rates[-2][0]:g}, {rates[-1][1]:.3g} at {rates[-1][0]:g}); a larger --kappa may reach it, with larger "
                 f"observer gains (checked only up to the ladder's end){shortened}")  # fmt: skip
        lmi, bounded = ("29" if joint else "46"), True
    else:
        lmi, bounded = ("29" if joint else "46"), False
        why = ("the loop's own decay must dominate its coupling with the observer and the diffusion" if joint else
               "its -sigma P^2 block must dominate the observer's coupling with the loop (K) and the diffusion")  # fmt: skip
        limit = (f"What binds is ({lmi}) itself, not kappa (the rate stopped growing with it): {why}" if len(rates) >= 2
                 else f"What binds is ({lmi}) itself" + (f" or kappa: only kappa = {rates[0][0]:g} gave an observer"
                                                         if rates else "") + f"; {why}") + shortened  # fmt: skip
    return Refusal(Refused.SETTLE, head, lmi=lmi, bounded=bounded, numbers=numbers,
                   detail=limit, advice="To accept a slower observer, design with --settle-within a longer window (0: "
                   "none) or give --alpha")  # fmt: skip


def finish(
    ts: TSModel, options: DesignOptions, resolved: Resolved, st: Structure, s3, K, s5, t0: float
) -> Design:
    """The design at the steps' point: the observer gains, the certificate (raised when it fails, unless
    ``options.allow_uncertified``), the reference input, the bounds, and the Design record."""
    aug, T, H, params = st.aug, st.T, st.H, dict(resolved.params)
    if getattr(s3, "beta", 0.0) > 0:  # the closed loop's decay rate the registered LMI "decay" certifies
        params["beta"] = float(s3.beta)
    if getattr(s5, "kappa", None) is not None and float(s5.kappa) != float(
        params.get("kappa", conditioned.KAPPA)
    ):
        params["kappa"] = float(s5.kappa)  # raised to settle within the fault windows (step5)
    status = list(resolved.notes) + list(st.notes)
    if options.variant == "paper":
        status.append(PAPER_NOTE)
    status += s3.notes + s5.notes
    X = s3.X
    P = np.linalg.inv(X)
    L1 = [np.linalg.solve(s5.Pbar, Q) for Q in s5.Q]
    R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
    L2 = [Ri @ H for Ri in R]
    Ls = T @ aug.Js  # T J1, or T [Bdbar_u J1] with Remark 5
    Kf, Kf_rules = _fault_gains(ts, status)
    u_ref, x_ref = u_reference(ts, K, status)
    if (missed := missed_motion(ts)) is not None:
        status.append(missed[1])
    sched, sources = scheduling_from_measurements(ts)
    plant = ts.plant
    total = time.perf_counter() - t0
    observer = {k: (float(v) if isinstance(v, (int, float, np.floating)) and v is not None else v)
                for k, v in s5.observer.items()}  # fmt: skip
    d = Design(
        plant=plant.name,
        plant_spec=options.plant_spec or plant.name,
        variant=options.variant,
        solver=options.solver,
        params=Params.from_mapping(params),
        dims=Dims.from_mapping(
            {"n": ts.n, "m": ts.m, "p": ts.p, "ld": ts.ld, "lf": ts.lf, "r": ts.r, "nbar": aug.nbar}
        ),
        premises=[p.to_dict() for p in ts.premises],
        local_models=ts.local_models,
        C=np.array(ts.C, dtype=float),
        Df=np.array(ts.Df, dtype=float),
        H=H,
        T=T,
        X=X,
        P=P,
        K=tuple(K),
        Kf=Kf,
        Kf_rules=Kf_rules,
        Pbar=s5.Pbar,
        Q=tuple(s5.Q),
        N=s5.N,
        theta=float(s5.theta),
        L1=tuple(L1),
        L2=tuple(L2),
        R=tuple(R),
        Ls=Ls,
        checks={},
        timings={"total_s": total, "solver_s": s3.seconds + s5.seconds},
        u_ref=u_ref,
        x_ref=x_ref,
        scheduling=sched,  # the record keeps it as data (scheduling_ops) and, for older readers, serialised
        plant_hash=plant_fingerprint(plant),
        vertices=ts.vertices,
        names=plant.names(sources),
        certified=False,
        status=status,
        solves={"step3": int(s3.solves), "step5": int(s5.solves), "total": int(s3.solves + s5.solves)},
        observer=Observer.from_mapping(observer),
        input_limits=None if plant.input_limits is None else np.array(plant.input_limits, dtype=float),
        x0=resolved.x0,
        remark5=st.r5doc,
        P29=getattr(s5, "P29", None),
    )
    # the certificate at the numbers the record holds, by the very function a loaded document is judged with
    checks = certify(d)
    checks["assumptions"] = [c.to_dict() for c in st.checks]
    # the plant's region (null: a state without bounds): the generated C checks y against its image
    checks["region"] = {
        side: [None if np.isnan(v) else float(v) for v in vals]
        for side, vals in (("lo", ts.plant.region_lo), ("hi", ts.plant.region_hi))
    }
    checks["alpha"] = float(s5.alpha)
    checks["loop"].update(
        beta=float(getattr(s3, "beta", 0.0)), why=getattr(s3, "beta_why", "as printed (paper variant)")
    )
    room = unsaturated(X, K, input_at_rest(ts, K, u_ref, x_ref), d.input_limits, _region(ts))
    if room is not None:
        if room["fraction"] is not None and room["fraction"] < SATURATES_EARLY and options.variant != "paper":
            # a reach that small: is it the gain's (another would do better) or the region's (none does)?
            room["fraction_max"] = reach_max(aug, params, room["headroom"], room["region_half_width"],
                                             options.solver)[0]  # fmt: skip
            if params.get("beta"):  # and without the loop's decay rate: is it the rate that binds?
                room["beta"] = float(params["beta"])
                room["fraction_max_without_decay"] = reach_max(aug, dict(params, beta=0.0), room["headroom"],
                                                               room["region_half_width"], options.solver)[0]  # fmt: skip
        checks["loop"]["unsaturated"] = room
    bad = failed(checks)
    if bad:
        what = "; ".join(f.text for f in bad)
        hint = (
            "use variant='conditioned'"
            if options.variant == "paper"
            else "raise sigma, or lower alpha, or try solver='SCS'"
        )
        msg = f"the design is not certified at the returned point: {what} does not hold; {hint}"
        if not options.allow_uncertified:
            lmis = [f.item for f in bad if f.item in LMIS]  # (46) first where it fails: step 3's (45) held
            raise InfeasibleDesignError(msg, result=checks, kind=Refused.CERTIFICATE,
                                        lmi="46" if "46" in lmis else next(iter(lmis), None))  # fmt: skip
        status.append("NOT CERTIFIED: " + msg)
    bounds = _bounds(not bad, d.R, K, Kf, Kf_rules, T, ts, u_ref, st.r5doc, getattr(s5, "bound", None))
    timings = dict(
        d.timings, total_s=time.perf_counter() - t0
    )  # "in all": the certificate and the bounds too
    return dataclasses.replace(
        d, checks=checks, certified=not bad, bounds=bounds, status=status, timings=timings
    )


def input_at_rest(ts: TSModel, K, u_ref=None, x_ref=None) -> np.ndarray:
    """The input that holds the reference: ``u_ref + sum_j h_j(x_ref) K_j x_ref`` (the ``u_eq`` of
    :func:`u_reference`, whatever K), or ``u_ref`` where the plant gives no ``x_ref``; ``u_ref, x_ref`` of
    :func:`u_reference` (found here where not given)."""
    if u_ref is None:
        u_ref, x_ref = u_reference(ts, K, [])
    if x_ref is None:
        return np.asarray(u_ref, dtype=float)
    return u_ref + sum(h * np.asarray(k) for h, k in zip(ts.memberships(x_ref), K)) @ x_ref


def _region(ts: TSModel) -> dict:
    """The plant's region as ``{"lo": [..], "hi": [..]}`` (nan: a state without a bound)."""
    return {"lo": list(ts.plant.region_lo), "hi": list(ts.plant.region_hi)}


def loop(ts: TSModel, st: Structure, resolved: Resolved, solver: str, *, search: bool = True):
    """Step 3's loop as the design keeps it: :func:`step3` (kappa searched with ``search``), its default rate
    lowered where it leaves the inputs no room (:func:`within_limits`)."""
    return within_limits(ts, st, resolved, step3(st, resolved, solver, search=search), solver)


def within_limits(ts: TSModel, st: Structure, resolved: Resolved, s3, solver: str):
    """Step 3's loop where its DEFAULT decay rate leaves the inputs no room: where the level set of ``x' X^-1 x``
    on which no input saturates reaches less than :data:`~fte_casadi.verdicts.SATURATES_EARLY` of the plant's
    region (:func:`~._recertify.unsaturated`), the loop is designed again at the default's lower rate, then with
    the smallest gain of (45) alone (as :func:`_loops` does for an observer the rate asks too much of), and the
    first whose reach is at least that is kept, else the one of the largest reach where it is ten times the
    default's; said so. A rate the user gave, and a plant without input limits, keep step 3's loop."""
    plant = ts.plant
    if plant.input_limits is None or resolved.beta is not None or not getattr(s3, "posed", False):
        return s3
    u0 = input_at_rest(ts, [s3.K] * st.aug.r)

    def reach(s):
        room = unsaturated(s.X, [s.K], u0, plant.input_limits, _region(ts))
        return None if room is None else room["fraction"]

    first = reach(s3)
    if first is None or first >= SATURATES_EARLY:
        return s3
    best, kept = first, s3
    because = (f"at {s3.beta:.4g} the loop keeps its inputs within their limits only on a set reaching {first:.2g} "
               "of the region (docs/design.md, 'Input limits')")  # fmt: skip
    for b in _lower_rates(s3):
        try:
            s3b = _loop_at(st, resolved, s3, solver, b, because)
        except (InfeasibleDesignError, conditioned.SolverFailedError):
            continue
        r = reach(s3b)
        if r is not None and r > best:
            best, kept = r, s3b
        if r is not None and r >= SATURATES_EARLY:
            return s3b
    return kept if best >= 10 * first else s3


#: the drift left at x_ref with the input that comes nearest, per state relative to that state's largest drift over the
#: region (about the share of the region the loop's resting point moves away from x_ref), above which :func:`u_reference`
#: warns that no input holds x_ref (a textbook's rounded steady state, 3e-5 of it, is not warned)
REST_RESIDUAL = 1e-3


def _drift_size(ts: TSModel, F, u, xr, samples: int = 64) -> np.ndarray:
    """Per state, the largest |drift| at ``samples`` points of the plant's region (a fixed draw; a state without
    bounds at its value in ``xr``) with the input ``u``: what a residual drift at x_ref is measured against."""
    lo, hi = ts.plant.region_lo, ts.plant.region_hi
    rng = np.random.default_rng(0)
    pts = np.tile(np.asarray(xr, dtype=float).reshape(-1, 1), samples)
    for j in range(ts.n):
        if np.isfinite(lo[j]) and np.isfinite(hi[j]):
            pts[j] = lo[j] + (hi[j] - lo[j]) * rng.random(samples)
    us = np.tile(np.asarray(u, dtype=float).reshape(-1, 1), samples)
    fx = F.map(samples)(pts, us, np.zeros((ts.ld, samples)), np.zeros((ts.lf, samples)))
    return np.max(np.abs(np.array(fx, dtype=float)), axis=1)


def u_reference(ts: TSModel, K, status: list):
    """``(u_ref, x_ref)``: the input that holds ``x_ref`` (the plant's ``u_ref`` where it gives one), its lines in
    ``status``."""
    plant = ts.plant
    if plant.u_ref is not None:
        return np.asarray(plant.u_ref, dtype=float).ravel(), None
    if plant.x_ref is None:
        return np.zeros(ts.m), None
    xr = np.asarray(plant.x_ref, dtype=float).ravel()
    F = plant.drift_function()
    ue = holding_input(plant, xr)
    rv = np.array(F(xr, ue, np.zeros(ts.ld), np.zeros(ts.lf)), dtype=float).ravel()
    res = float(np.linalg.norm(rv))
    share = np.abs(rv) / np.maximum(_drift_size(ts, F, ue, xr), 1e-300)
    if np.max(share) > REST_RESIDUAL:  # no input holds the plant at x_ref, by more than round-off or rounding
        k = int(np.argmax(share))
        unit = plant.state_units[k] if plant.state_units[k] else "units"
        status.append(f"warning: x_ref is not an equilibrium of the plant: no input holds it there (with the input that "
                      f"comes nearest, u_eq = {np.round(ue, 6).tolist()}, {plant.state_names[k]} still moves at "
                      f"{rv[k]:.3g} {unit} per {plant.time_unit}, {share[k]:.2g} of its largest rate over the region), "
                      "so the loop rests at another point than x_ref: give b.reference a state where the plant can "
                      "rest")  # fmt: skip
    lim = plant.input_limits
    if lim is not None and np.any((ue < lim[:, 0]) | (ue > lim[:, 1])):
        status.append(f"warning: the input holding x_ref, u_eq = {np.round(ue, 6).tolist()}, lies outside the input "
                      f"limits {np.asarray(lim).tolist()}: the loop saturates at rest")  # fmt: skip
    h = ts.memberships(xr)
    Kx = sum(h[j] * K[j] for j in range(len(K)))
    status.append(f"u_ref = u_eq - (sum_j h_j(x_ref) K_j) x_ref with u_eq = {np.round(ue, 6).tolist()} holding the "
                  f"nonlinear plant at x_ref (drift residual {res:.2g}); u = u_eq + K (xhat - x_ref)")  # fmt: skip
    return ue - Kx @ xr, xr


def _scaling_note(ts: TSModel) -> str:
    """Where the local models' coefficients span more than 1e10, a sentence saying that the rank decisions
    behind an assumption's verdict are made at a tolerance relative to the largest one ('' otherwise)."""
    big, small, where = 0.0, np.inf, ""
    for i, lm in enumerate(ts.local_models):
        for key in ("A", "B", "Bd", "Bf"):
            M = np.abs(np.asarray(lm[key], dtype=float))
            nz = M[M > 1e-12 * M.max()] if M.size else M  # not the round-off of an exact zero
            if nz.size and nz.max() > big:
                k = np.unravel_index(np.argmax(M), M.shape)
                big, where = (
                    float(nz.max()),
                    f"{key}[{k[0] + 1}, {k[1] + 1}] = {float(lm[key][k]):.3g} in rule {i + 1}",
                )
            if nz.size:
                small = min(small, float(nz.min()))
    if not (big > 0 and small < np.inf and big / small > 1e10):
        return ""
    return (
        f" Note: the plant's coefficients span a factor {big / small:.1e} (largest {where}, "
        f"smallest {small:.3g}); the rank decisions behind this verdict use a tolerance relative to the largest, so "
        "it may come from that scaling rather than from the plant's structure: rescale its units (states, inputs) "
        "so that its coefficients lie within about 1e6 of each other, and design again."
    )


def _fault_gains(ts: TSModel, status: list):
    """``(Kf, Kf_rules)``: the fault compensation ``Kf_i = -pinv(B_i) Bf_i``, one for all rules when they agree."""
    Kfs = [-np.linalg.pinv(lm.B) @ lm.Bf for lm in ts.local_models]
    Kf, Kf_rules = Kfs[0], None
    # B_i and Bf_i may both vary (an actuator fault enters where u does: Bf = B E) and still give one Kf
    spread = max(float(np.max(np.abs(Ki - Kfs[0]))) for Ki in Kfs)
    if spread > 1e-9 * max(1.0, float(np.max(np.abs(Kfs[0])))):
        Kf_rules = tuple(Kfs)
        status.append(f"Kf scheduled: -pinv(B_i) Bf_i differs between rules (by up to {spread:.3g}); the step blends "
                      "Kf(h) = sum_i h_i Kf_i (document: Kf_rules; Kf is rule 1's)")  # fmt: skip
    return Kf, Kf_rules


def _closed_loop_view(ts: TSModel, T, K, r5doc, gains=None, u_ref=None, **known):
    """The closed loop's data the bound needs (:mod:`fte_casadi.design.core._bounds`), or None where it is not posed
    (Remark 5's fallback, Theorem 5's diffusion). ``gains = (Kf, Kf_rules)`` and ``u_ref`` once the design has
    them (before step 5 they are computed here, their messages left to the design); ``known``: ``R`` once the
    observer is designed."""
    if (r5doc and r5doc.get("used")) or any(lm.has_diffusion_extension for lm in ts.local_models):
        return None
    scratch: list = []
    Kf, Kf_rules = _fault_gains(ts, scratch) if gains is None else gains
    u_ref = u_reference(ts, K, scratch)[0] if u_ref is None else u_ref
    return SimpleNamespace(dims=SimpleNamespace(n=ts.n, lf=ts.lf), T=T, u_ref=u_ref, Kf=Kf, Kf_rules=Kf_rules, r=ts.r,
                           local_models=ts.local_models, K=K, **known)  # fmt: skip


def _bounds(certified, R, K, Kf, Kf_rules, T, ts, u_ref, r5doc, fallback=None) -> dict:
    """The certified bounds on the fault- and state-estimation errors at the returned design (
    :mod:`fte_casadi.design.core._bounds`), for a certified design; {} otherwise."""
    if not certified:
        return {}
    if r5doc and r5doc.get("used"):
        why = {"holds": False, "why": "not computed where Remark 5's fallback is used"}
        return {"fault_error": why, "state_error": dict(why)}
    from .core._bounds import fault_error_bound, state_error_bound

    view = _closed_loop_view(ts, T, K, None, (Kf, Kf_rules), u_ref, R=R)
    if view is None:  # Theorem 5's diffusion: the bounds say so
        view = SimpleNamespace(local_models=ts.local_models)
    fe = fault_error_bound(view, fallback=fallback)
    return {"fault_error": fe, "state_error": state_error_bound(view, start=fe)}


def _named(checks: list, aug, ts: TSModel, accepted=()) -> list:
    """The failed assumptions (1) and (2) with the faults and unknown inputs behind them named, and the
    measurement that would separate them (:mod:`fte_casadi.design._structure`); the first failed of (2) and (4)
    not ``accepted`` says where the model's form hides a state's effect (:mod:`fte_casadi.design._model_form`)."""
    import dataclasses

    from ._model_form import hidden_effects
    from ._structure import describe

    out, form, acc = [], None, accepted_names(accepted)
    for c in checks:
        if not c.holds and c.name in ("(1)", "(2)"):
            why = describe(aug, ts.plant, {c.name})
            if why:
                c = dataclasses.replace(c, message=f"{c.message}. Which: {why}")
        if (
            not c.holds
            and c.name in ("(2)", "(4)")
            and acc is not None
            and c.name not in acc
            and form is None
        ):
            form = (
                hidden_effects(ts, check=c.name == "(2)") or False
            )  # the check re-derives: (2) is what it tests
            if form:
                c = dataclasses.replace(c, message=f"{c.message}. But {form.render(ts.plant)}")
        out.append(c)
    return out
