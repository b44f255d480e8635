"""The text ``fte design`` prints for a design: its certificate, observer, bound, timings and notes."""

from __future__ import annotations

import numpy as np

from ..verdicts import SATURATES_EARLY
from .core._certify import certified_by
from .core._lmis import LMIS, THEOREM1, routes

__all__ = []  # public: docs/api.md


def _lmi_keys(checks: dict) -> list[str]:
    """The keys of the registered LMIs the certificate holds (:data:`~.core._lmis.LMIS`), then under Theorem 5
    their Theorem 5 numbers (the same values)."""
    lmi = checks["lmi_max_eig"]
    keys = [k for k in LMIS if k in lmi]
    if checks.get("theorem") == 5:
        keys += [e.theorem5 for e in LMIS.values() if e.theorem5 and e.theorem5 in lmi]
    return keys


def _idle_loop(loop: dict) -> str:
    """A warning where the controller does not act (``gain_ratio`` below :data:`~._limits.IDLE_GAIN`, the threshold
    ``fte simulate``'s verdicts use) and the open loop decays: it already holds the rate the loop is certified for,
    so step 3's smallest gain is zero in effect. "" where the loop acts."""
    from ._limits import IDLE_GAIN

    ratio, ol = loop.get("gain_ratio"), loop.get("open_loop_decay")
    if ratio is None or not ratio < IDLE_GAIN or ol is None or not ol > 0:
        return ""
    return (
        f"  warning: the controller does not act: max ||B_i K|| / max ||A_i|| = {ratio:.2g}. The open loop "
        f"already decays at {ol:.4g} per rule and the loop is certified for {loop['decay_certified']:.4g} at any "
        "blending, a rate that asks no feedback: step 3's smallest gain is zero in effect. Without tolerant control "
        "the faults meet only the plant's own decay; with it they meet Kf fhat alone, and a sensor fault's own "
        "estimate enters u through no term. A rate asked with --beta makes the loop act only where the open loop "
        "does not already hold it and (45) allows it"
    )


def _certified_by(checks: dict) -> str:
    """Which certificate holds (:func:`~.core._certify.certified_by`): Theorem 3's (45)-(46), or Theorem 1's (29)
    where they do not (then (46) is shown above but not required)."""
    held = (
        checks["certified_by"] if "certified_by" in checks else certified_by(checks)
    )  # older documents: computed
    theorem = checks.get("theorem")
    offered = routes()
    if held is None or held not in offered:
        return (
            "  certificate: no route of "
            + " or ".join(
                "(" + ", ".join(LMIS[k].name(theorem) for k in keys) + ")" for keys in offered.values()
            )
            + " holds"
        )
    names = ", ".join(LMIS[k].name(theorem) for k in offered[held])
    common = ", ".join(lmi.name(theorem) for lmi in LMIS.values() if not lmi.route)
    first = next(iter(offered))
    lam, eps = checks["lmi_max_eig"], checks.get("lmi_roundoff", {})
    failed = [LMIS[k].name(theorem) for k in offered[first] if not lam.get(k, 0.0) < -eps.get(k, 0.0)]
    rest = "" if held == first or not failed else f" ({', '.join(failed)}: not required, and not holding)"
    return f"  certified by {held}'s {names}, with {common}{rest}"


def _unsaturated_line(room: dict, states: list) -> str:
    """The summary's line on where the input limits leave the loop's certificate intact
    (:func:`~._recertify.unsaturated`)."""
    names = [states[k] if k < len(states) else f"x{k}" for k in range(len(room["extent"]))]
    reach = ", ".join(f"{nm} {v:.3g}" + (f" of {h:.3g}" if h is not None else "")
                      for nm, v, h in zip(names, room["extent"], room["region_half_width"]))  # fmt: skip
    frac = room.get("fraction")
    text = (
        "  input limits: u stays within them, and step 3's V = x' X^-1 x (about x_ref) decreases, on its level set "
        f"reaching, from x_ref, {reach} (the region's half-width); beyond it an input saturates, which the "
        "certificate does not cover (with the estimate exact and no disturbance: the observer's error and the noise are not in it)"
    )
    if frac is not None and frac < SATURATES_EARLY:
        text += (
            f"\n  warning: that is {frac:.2g} of the region: the controller saturates its input for deviations "
            "that small, and the loop that runs is not the loop certified (docs/design.md, 'Input limits')"
        )
        best, free = room.get("fraction_max"), room.get("fraction_max_without_decay")
        if best is not None:
            rate = f" and the LMI 'decay' at beta = {room['beta']:.4g}" if room.get("beta") else ""
            text += f"; the largest reach any common gain allows under (45){rate} at these parameters is {best:.2g}"
            if best >= SATURATES_EARLY:
                text += ": a gain with a larger reach exists, and step 3 does not weigh the input limits"
            elif free is not None and free >= SATURATES_EARLY:
                text += f", under (45) alone {free:.2g}: the loop's decay rate leaves the input no room"
            else:
                text += ": the region, not the gain, binds (the input limits cannot hold the plant over it)"
    return text


def design_summary(d) -> str:
    """The summary of the Design ``d`` that ``fte design`` prints (one string, lines joined)."""
    c = d.checks
    lmi = c["lmi_max_eig"]
    shown = _lmi_keys(c)
    K = max(float(np.max(np.abs(k))) for k in d.K)
    obs = d.observer
    lines = [
        f"design of {d.plant}: variant {d.variant}, solver {d.solver}, "
        f"{'CERTIFIED' if d.certified else 'NOT CERTIFIED'}"
        + (" (by Theorem 1's (29))" if d.certified and c.get("certified_by") == THEOREM1 else ""),
        "  params: " + ", ".join(f"{k} = {v:g}" for k, v in d.params.to_dict().items()),
        "  largest eigenvalue of each LMI at the returned point, balanced (D L D, D = diag(|L_kk|^-1/2): the same "
        "definiteness; it holds below minus its round-off): "
        + ", ".join(f"({k}) {lmi[k]:.3g}" for k in shown)
        + (
            "; round-off of each, 8 dim eps ||D L D||: "
            + ", ".join(f"{c['lmi_roundoff'][k]:.1g}" for k in shown if k in c["lmi_roundoff"])
            if c.get("lmi_roundoff")
            else ""
        ),
        _certified_by(c),
        f"  theta = {d.theta:.3g}, cond(Pbar) = {c['cond_Pbar']:.3g}, max|L1| = {c['max_abs_L1']:.3g}, max|K| = {K:.3g}",
        f"  observer: max Re eig(R_i) = {c['R_max_real_eig']:.4g}; closed loop: max Re eig(A_i + B_i K_j) = "
        f"{c['closed_loop_max_real_eig']:.4g}; discrete observer stable for Ts < {c['ts_max']:.4g}",
    ]
    loop = c.get("loop")
    if loop:
        held = f", the LMI 'decay' at beta = {loop['beta']:.4g}" if loop.get("beta") else ""
        lines.append(
            f"  closed loop: decays at {loop['decay_certified']:.4g} or faster for any blending of the rules "
            f"(certified{held}), at {loop['decay_spectral']:.4g} per rule (eigenvalues); the open loop at "
            f"{loop['open_loop_decay']:.4g}; max ||B_i K|| / max ||A_i|| = {loop['gain_ratio']:.3g}"
            + (f"; {loop['why']}" if loop.get("why") else "")
        )
        idle = _idle_loop(loop)
        if idle:
            lines.append(idle)
    room = (loop or {}).get("unsaturated")
    if room and room.get("extent"):
        lines.append(_unsaturated_line(room, (d.names or {}).get("states") or []))
    disc = c.get("discrete")
    if disc:
        lines.append(
            f"  discrete step at the sample time Ts = {disc['sample_time']:g}: "
            + ("proven stable" if disc["holds"] else "NOT proven stable")
            + f" for any blending of the rules (Pbar decreases for Ts < {disc['ts_max_lyapunov']:.4g})"
        )
    for key, what, err in (("fault_error", "fault", "f - fhat"), ("state_error", "state", "x - xhat")):
        fb = (d.bounds or {}).get(key)
        if fb and fb.get("holds"):
            lines.append(f"  certified bound on the {what}-estimation error: E int |{err}|^2 dt <= "
                         + " + ".join(f"{g:.3g}^2 t" if c == "const" else f"{g:.3g}^2 E int |{c}|^2" for c, g in fb["gains"].items())
                         + " + E xi0' P xi0 (docs/tune.md)")  # fmt: skip
        elif fb:
            lines.append(f"  no bound on the {what}-estimation error: {fb.get('why')}")
    if obs.alpha is not None:
        lines.append(f"  observer decay rate alpha = {obs.alpha:.4g}: {obs.why or ''}")
    solves = f", {d.solves.get('total')} conic solves" if d.solves else ""
    lines.append(
        f"  time: {d.timings['total_s']:.2f} s in all, {d.timings['solver_s']:.2f} s in the solver{solves}"
    )
    lines += [
        f"  {s}" if s.startswith("warning: ") else f"  note: {s}" for s in d.status
    ]  # a warning says so
    return "\n".join(lines)
