"""Remark 5 in use: when H cannot decouple the unknown inputs (or decoupling them costs observability),
the sliding term attenuates what H leaves, and a rule-dependent ``Bd_i`` is named as the cause.

When it applies (:func:`fallback`)
    - assumption (1) fails: H decouples the directions of d the outputs see, the sliding term the
      rest (the paper's Remark 5);
    - assumption (4) fails although ``(Abar_i, Cbar)`` is observable: decoupling every direction of
      ``[Bdbar_1 ... Bdbar_r]`` made the pair unobservable. This is what a rule-dependent ``Bd_i``
      does: one unknown input enters along r directions and H decouples all of them (for
      example the cart-pole with a torque through ``1/den(theta)``). Then H decouples less — the mean
      direction of each unknown input over the rules, else nothing — and the sliding term
      attenuates the rest, if that makes (4) hold.

What the sliding gain bounds
    The paper's ``u_s = (delta + eps) sgn(s)`` dominates ``f''`` (``|f''| <= delta``); Remark 5 puts
    ``df = [d; f'']`` in place of ``f''``, so read literally the same delta bounds d. Each undecoupled
    direction k gets ``sum_j max_i |M_i[k, j]| d_bound_j + eps`` (``T Bdbar_i = Bdbar_u M_i``;
    :meth:`~fte_casadi.design._uio.Remark5.gains`), a bound on ``|(M(h) d)_k|``, with ``d_bound = delta``
    by default (Remark 5 as printed) or a bound on ``|d_j|`` given as ``d_bound`` (``--d-bound``), the
    gain the Lyapunov argument asks for. That argument also needs (20) for the widened ``J``, and where H leaves
    a direction the outputs do not see (``Cbar Bdbar_u = 0``, always so when assumption (1) fails) (20)
    cannot hold for it, exactly as for ``J1`` (docs/method.md, equality (20)): a relay of the full bound then competes with the
    fault estimate for the same residual. docs/remark5.md measures both choices on the test plants; the
    nominal default estimated the faults better in every case measured.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ..errors import ParameterError
from ._augment import Augmented
from ._uio import (
    AssumptionCheck,
    Remark5,
    check_assumptions,
    check_observability,
    column_compress,
    rank,
    remark5_split,
)

__all__ = ["fallback", "record"]  # public: docs/api.md


def rule_dependent_directions(
    aug: Augmented, which: str = "Bd"
) -> list[tuple[int, list[tuple[int, int, int]]]]:
    """The columns of ``Bd_i`` (``which="Bd"``) or ``Bf_i`` (``"Bf"``) whose direction changes between
    rules: ``[(column, [(rule a, rule b, entry), ...]), ...]``, each entry where rule b's column,
    scaled to rule a's, differs (0-based indices)."""
    n, lf = aug.n, aug.lf
    cols = [B[:n] for B in aug.Bdbar] if which == "Bd" else [A[:n, n + lf :] for A in aug.Abar]
    out = []
    for j in range(cols[0].shape[1]):
        V = np.stack([c[:, j] for c in cols], axis=1)  # n x r
        if rank(V) <= 1:
            continue
        a = int(np.argmax(np.linalg.norm(V, axis=0)))
        diffs = []
        for b in range(aug.r):
            if b == a or not np.any(V[:, b]):
                continue
            scale = float(V[:, a] @ V[:, b]) / float(V[:, a] @ V[:, a])
            d = V[:, b] - scale * V[:, a]
            tol = 1e-9 * max(np.abs(V).max(), 1e-300)
            diffs += [(a, b, k) for k in range(n) if abs(d[k]) > tol]
        out.append((j, diffs))
    return out


def explain_rule_dependence(aug: Augmented, plant, which: str = "Bd") -> str:
    """Words for :func:`rule_dependent_directions`: which input, which rules, which entries and their range."""
    n, lf = aug.n, aug.lf
    names = plant.unknown_input_names if which == "Bd" else plant.fault_names
    kind = "unknown input" if which == "Bd" else "fault"
    cols = [B[:n] for B in aug.Bdbar] if which == "Bd" else [A[:n, n + lf :] for A in aug.Abar]
    parts = []
    for j, diffs in rule_dependent_directions(aug, which):
        vals = np.array([c[:, j] for c in cols])  # r x n
        entries = [k for k in range(n) if np.ptp(vals[:, k]) > 1e-9 * max(np.abs(vals).max(), 1e-300)]
        rules = sorted({b + 1 for _, b, _ in diffs} | {a + 1 for a, _, _ in diffs})
        rng = ", ".join(
            f'"{plant.state_names[k]}" from {min(c[k, j] for c in cols):.4g} to {max(c[k, j] for c in cols):.4g}'
            for k in entries
        )
        parts.append(f'{kind} "{names[j]}" enters along a direction that changes between rules {rules} '
                     f"(entries {rng})")  # fmt: skip
    return "; ".join(parts)


def _candidates(aug: Augmented, one_fails: bool, rule_dep: bool):
    """Decoupled directions D to try, with why: the visible part (when (1) fails), the mean direction of
    each unknown input over the rules (when Bd_i depends on the rule), nothing (H = 0)."""
    out = []
    if one_fails:
        out.append((None, "H cannot decouple every unknown input"))
    if rule_dep:
        mean = column_compress(sum(aug.Bdbar) / aug.r)
        if mean.shape[1] and rank(aug.Cbar @ mean) == mean.shape[1]:
            out.append(
                (
                    mean,
                    "Bd_i depends on the rule: H decouples each unknown input's mean direction over the rules",
                )
            )
    out.append((np.zeros((aug.nbar, 0)), "H decouples nothing"))
    return out


def fallback(aug: Augmented, checks: list[AssumptionCheck], enabled: bool = True) -> Remark5 | None:
    """Remark 5's split to use, or None (not needed, not enabled, or no split makes (4) hold).

    ``checks`` are the five checks with the full decoupling. When (1) fails, the visible part is
    decoupled (the paper's fallback), or less when that leaves (4) failing. When only (4) fails and
    ``(Abar_i, Cbar)`` itself is observable, decoupling is what costs observability: less is decoupled
    if that makes (4) hold."""
    one, four = checks[0], checks[3]
    if not enabled or aug.ld == 0 or (one.holds and four.holds):
        return None
    if one.holds and not check_observability(aug, np.eye(aug.nbar)).holds:
        return None  # (4) fails without any decoupling: Remark 5 cannot help
    rule_dep = bool(rule_dependent_directions(aug))
    first = None
    for D, why in _candidates(aug, not one.holds, rule_dep):
        r5 = remark5_split(aug, D, why)
        if r5 is None:
            continue
        first = first or r5
        wide = dataclasses.replace(aug, Jd=r5.Bdu)
        if all(c.holds for c in check_assumptions(wide, r5.T, remark5=r5)[2:4]):
            return r5
    return first if not one.holds else None


def resolve_d_bound(d_bound, ld: int, input_names, delta: float) -> tuple[np.ndarray, str]:
    """``d_bound`` as one non-negative bound per unknown input (``delta`` for each when None: Remark 5 read
    literally), and where it came from; a ParameterError saying what to give when it is malformed."""
    if d_bound is None:
        return np.full(ld, float(delta)), "delta, as Remark 5 prints it (delta bounds [d; f''])"
    a = np.atleast_1d(np.asarray(d_bound, dtype=float)).ravel()
    if a.size == 1:
        a = np.full(ld, float(a[0]))
    if a.size != ld or not np.all(np.isfinite(a)) or np.any(a < 0):
        raise ParameterError(
            f"d_bound must be one non-negative finite number, or one per unknown input ({ld}: "
            f"{', '.join(input_names)}); got {d_bound!r}"
        )
    return a, "as given (d_bound)"


def record(r5: Remark5, d_bound, params: dict, input_names) -> dict:
    """The design document's ``remark5`` key (``d_bound`` checked by :func:`resolve_d_bound`)."""
    d_bound, source = resolve_d_bound(d_bound, len(input_names), list(input_names), params["delta"])
    epsilon = params["epsilon"]
    covered = [input_names[j] for j in r5.inputs]
    return {
        "used": True,
        "unknown_inputs": covered,
        "message": (
            f"Remark 5: {r5.why}; the sliding term attenuates unknown input(s) "
            + ", ".join(f'"{n}"' for n in covered)
            + f" along {r5.Bdu.shape[1]} direction(s) H leaves (J1 -> [Bdbar_u J1], f'' -> [M(h) d; f'']), "
            f"with gains {', '.join(f'{g:.4g}' for g in r5.gains(d_bound, epsilon))} for |d| <= "
            f"{', '.join(f'{v:g}' for v in d_bound)}, {source}"
        ),
        "why": r5.why,
        "decoupled_directions": int(r5.D.shape[1]),
        "attenuated_directions": int(r5.Bdu.shape[1]),
        "Bdu": r5.Bdu.tolist(),
        "M": [Mi.tolist() for Mi in r5.M],
        "d_bound": [float(v) for v in d_bound],
        "d_bound_source": source,
        "gain": [float(v) for v in r5.gains(d_bound, epsilon)],
    }


def explain_causes(
    checks: list[AssumptionCheck], aug: Augmented, plant, enabled: bool
) -> list[AssumptionCheck]:
    """A failed (4) (or (1)) whose cause is a rule-dependent ``Bd_i`` says so: which unknown input, which
    rules and entries, and what helps. A failed (4) with a non-decaying unobservable eigenvalue cannot be
    accepted with success (no observer gain moves that eigenvalue): it is marked not acceptable."""
    out = []
    dep = explain_rule_dependence(aug, plant) if aug.ld else ""
    k = rank(np.hstack(aug.Bdbar)) if aug.ld else 0
    for c in checks:
        if not c.holds and c.name in ("(1)", "(4)") and dep and k > aug.ld:
            if enabled:
                tried = ("Remark 5's attenuation was tried (H decoupling less: each input's mean direction, or "
                         "nothing) and does not make (3) and (4) hold")  # fmt: skip
            else:
                r5 = fallback(aug, checks, True)
                if r5 is not None and not all(c.holds for c in check_assumptions(with_remark5(aug, r5), r5.T,
                                                                                   remark5=r5)[2:4]):  # fmt: skip
                    r5 = None
                tried = (f"Remark 5's attenuation, which makes (3) and (4) hold here ({r5.why}): leave it on "
                         "(drop --no-remark5 / remark5=False)" if r5 is not None else
                         "Remark 5's attenuation does not make (3) and (4) hold here")  # fmt: skip
            c = dataclasses.replace(c, message=(
                f"{c.message}. The cause is a rule-dependent Bd_i: {dep}, so H must decouple "
                f"rank [Bd_1 ... Bd_r] = {k} directions for {aug.ld} unknown input(s), using up outputs. What helps: "
                "a premise-independent direction (write the plant so that the unknown input enters every rule "
                f"along the same direction); {tried}; or a measurement of a further state"))  # fmt: skip
        if not c.holds and c.name == "(4)":
            c = dataclasses.replace(c, acceptable=False)
        out.append(c)
    return out


def with_remark5(aug: Augmented, r5: Remark5 | None) -> Augmented:
    """``aug`` with the sliding directions widened to ``[Bdbar_u J1]`` (unchanged without Remark 5)."""
    return aug if r5 is None else dataclasses.replace(aug, Jd=r5.Bdu)
