"""A-posteriori certificates: every LMI rebuilt with numpy at the returned point.

Nothing here touches cvxpy: the left sides of every registered LMI (:data:`~._lmis.LMIS`: (45)/(78),
(46)/(79), (55)/(80), (64)/(81)) are assembled again from the plain matrices (X, Y_j = K_j X, P, Pbar, Q_i,
N, theta), so a solver that reports "optimal" at a point where an LMI does not hold is caught.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ._linalg import sym as _sym
from ._lmis import LMIS, THEOREM1, distinct, routes

__all__ = ["certificate", "ts_max", "lyapunov_ts_max", "discrete_certificate", "balanced", "eig_roundoff",
           "failures", "failed", "Failure", "certified_by"]  # fmt: skip


def _maxeig(L: np.ndarray) -> float:
    return float(np.max(np.linalg.eigvalsh(L))) if L.size else -np.inf


def eig_roundoff(L: np.ndarray) -> float:
    """Bound on the round-off of a computed eigenvalue of the symmetric ``L``: 8 dim eps ||L||_2.

    Forming ``L`` from the design's matrices and ``eigvalsh`` are backward stable, so an
    eigenvalue recomputed elsewhere (another BLAS, another CPU) moves by a few eps * dim * ||L||_2.
    A largest eigenvalue within this bound of zero certifies nothing.
    """
    return float(8 * L.shape[0] * np.finfo(float).eps * np.linalg.norm(L, 2)) if L.size else 0.0


def balanced(L: np.ndarray) -> np.ndarray:
    """``D L D`` with ``D = diag(|L_kk|^-1/2)`` (1 where ``L_kk = 0``): the same definiteness as ``L``.

    An LMI whose blocks live on different scales (``-theta I`` with theta = 1e14 beside ``-I``, as in
    (55) for a slow plant, whose Pbar is large in seconds) has a largest eigenvalue far below the
    round-off bound of its largest entries although its sign is not in doubt; after this congruence
    every diagonal entry is -1 or +1 and the round-off bound measures what matters.
    """
    d = np.abs(np.diag(L))
    D = np.where(d > 0, 1.0 / np.sqrt(np.where(d > 0, d, 1.0)), 1.0)
    return (L * D).T * D


def _block_max(L: np.ndarray, sizes) -> list[float]:
    out, k = [], 0
    for b in sizes:
        out.append(_maxeig(L[k : k + b, k : k + b]) if b else float("-inf"))
        k += b
    return out


def ts_max(R: list[np.ndarray]) -> float:
    """Largest Ts with spectral radius of ``I + Ts R_i`` below one for every rule (explicit Euler).

    Per eigenvalue ``lam = a + jb`` (a < 0): ``|1 + Ts lam| < 1`` iff ``Ts < -2 a / |lam|^2``.
    Zero when some R_i is not Hurwitz.
    """
    best = np.inf
    for Ri in R:
        for lam in np.linalg.eigvals(Ri):
            if lam.real >= 0:
                return 0.0
            best = min(best, -2.0 * lam.real / abs(lam) ** 2)
    return float(best)


def lyapunov_ts_max(R: list[np.ndarray], Pbar: np.ndarray) -> float:
    """Largest Ts for which ``V(e) = e^T Pbar e`` decreases along the discrete step of every rule.

    ``(I + Ts R_i)^T Pbar (I + Ts R_i) - Pbar = Ts (S_i + Ts G_i)`` with ``S_i = R_i^T Pbar + Pbar R_i``
    and ``G_i = R_i^T Pbar R_i >= 0``: negative definite iff ``S_i < 0`` and ``Ts < 1 / lambda_max(G_i,
    -S_i)`` (generalised eigenvalue). One Pbar for all rules, and the left side is convex in the step
    matrix, so this bounds the *blended* discrete observer ``z+ = sum_i h_i (I + Ts R_i) z`` for any
    memberships, unlike the per-rule eigenvalues of :func:`ts_max`. Zero when some ``S_i`` is not < 0.
    """
    best = np.inf
    for Ri in R:
        S = _sym(Ri.T @ Pbar + Pbar @ Ri)
        if not np.linalg.eigvalsh(S).max() < 0:
            return 0.0
        G = Ri.T @ Pbar @ Ri
        L = np.linalg.cholesky(-S)  # -S = L L^T; eigenvalues of L^-1 G L^-T
        Li = np.linalg.inv(L)
        lam = np.linalg.eigvalsh(Li @ _sym(G) @ Li.T).max()
        best = min(best, 1.0 / lam if lam > 0 else np.inf)
    return float(best)


def discrete_certificate(R: list[np.ndarray], Pbar: np.ndarray, sample_time: float) -> dict:
    """The discrete step at ``sample_time`` (Ts) checked with Pbar: the largest eigenvalue of
    ``(I + Ts R_i)^T Pbar (I + Ts R_i) - Pbar`` over the rules, relative to ``||Pbar||`` (negative:
    certified for any blending of the rules), and the largest Ts this holds for."""
    n = Pbar.shape[0]
    worst = max(
        float(
            np.linalg.eigvalsh(
                (np.eye(n) + sample_time * Ri).T @ Pbar @ (np.eye(n) + sample_time * Ri) - Pbar
            ).max()
        )
        for Ri in R
    )
    rel = worst / float(np.linalg.norm(Pbar, 2))
    return {
        "sample_time": float(sample_time),
        "max_eig_rel": rel,
        "ts_max_lyapunov": lyapunov_ts_max(R, Pbar),
        "holds": bool(rel < -8 * n * np.finfo(float).eps),
    }


def lmi_matrices(aug, d: dict, params: dict):
    """Yield ``(lmi, matrix)`` for every left side of every registered LMI (:data:`~._lmis.LMIS`) at the design
    point ``d``: (45) and (46) for every rule and distinct gain, (55) once, (64) for every rule. Each must be
    negative definite."""
    for lmi in LMIS.values():
        for L in lmi.matrices(aug, d, params):
            yield lmi, L


def certificate(aug, d: dict, params: dict) -> dict:
    """Recompute every registered LMI at the design point ``d`` (X, K, P, T, Pbar, Q, N, theta, R, L1, and P29 for
    a design certified by Theorem 1's (29): None or absent otherwise).

    Returns the ``checks`` dictionary of the design document. Each LMI is judged in ONE form, its balanced
    one (:func:`balanced`: ``D L D``, the same definiteness, every diagonal entry -1 or +1), whose largest
    eigenvalue is ``lmi_max_eig`` (a margin relative to the LMI's own diagonal) and whose round-off bound is
    ``lmi_roundoff``: the LMI holds iff ``lmi_max_eig < -lmi_roundoff`` (:func:`failures`). The form printed is
    the form certified. The left side as posed (its blocks on their own scales) is kept for reference as
    ``lmi_raw_max_eig`` and ``lmi_raw_roundoff``; ``lmi_balanced_*`` repeat ``lmi_max_eig``/``lmi_roundoff``
    for readers of older documents.
    """
    X, K, Pbar, theta = d["X"], d["K"], d["Pbar"], d["theta"]
    sizes = {k: list(lmi.blocks(aug)) for k, lmi in LMIS.items()}
    lm = dict.fromkeys(LMIS, -np.inf)
    blocks = {k: [-np.inf] * len(v) for k, v in sizes.items()}
    roundoff = dict.fromkeys(lm, 0.0)
    lm_bal, roundoff_bal = dict(lm), dict(roundoff)
    evaluated = set()
    for lmi, L in lmi_matrices(aug, d, params):
        key = lmi.key
        evaluated.add(key)
        eig = (lambda M, lmi=lmi, key=key: lmi.max_eig(M, sizes[key])) if lmi.max_eig is not None else _maxeig
        lm[key] = max(lm[key], eig(L))
        roundoff[key] = max(roundoff[key], eig_roundoff(L))
        Lb = balanced(L)
        lm_bal[key] = max(lm_bal[key], eig(Lb))
        roundoff_bal[key] = max(roundoff_bal[key], eig_roundoff(Lb))
        blocks[key] = [max(a, b) for a, b in zip(blocks[key], _block_max(L, sizes[key]))]
    # an LMI with no left side at this point (Theorem 1's (29) of a design without P29) is not in the certificate
    for table in (lm, blocks, roundoff, lm_bal, roundoff_bal):
        for key in [k for k in table if k not in evaluated]:
            del table[key]
    r, js = aug.r, distinct(K)
    cl = max(float(np.max(np.linalg.eigvals(aug.Abar[i][: aug.n, : aug.n] + aug.Bbar[i][: aug.n] @ K[j]).real))
             for i in range(r) for j in js)  # fmt: skip
    R = d["R"]
    ev_P = np.linalg.eigvalsh(_sym(Pbar))
    ev_X = np.linalg.eigvalsh(_sym(X))
    checks = {
        "lmi_max_eig": dict(lm_bal),
        "lmi_roundoff": dict(roundoff_bal),
        "lmi_block_max_eig": blocks,
        "lmi_raw_max_eig": lm,
        "lmi_raw_roundoff": roundoff,
        "lmi_balanced_max_eig": dict(lm_bal),
        "lmi_balanced_roundoff": dict(roundoff_bal),
        "X_min_eig": float(ev_X[0]),
        "Pbar_min_eig": float(ev_P[0]),
        "R_max_real_eig": float(max(np.max(np.linalg.eigvals(Ri).real) for Ri in R)),
        "closed_loop_max_real_eig": cl,
        "cond_Pbar": float(ev_P[-1] / ev_P[0]) if ev_P[0] > 0 else float("inf"),
        "max_abs_L1": float(max(np.max(np.abs(L)) for L in d["L1"])),
        "max_abs_K": float(max(np.max(np.abs(Kj)) for Kj in K)),
        "theta": float(theta),
        "ts_max": ts_max(R),
    }
    if d.get("P29") is not None:
        checks["P29_min_eig"] = float(np.linalg.eigvalsh(_sym(d["P29"]))[0])
    if any(np.any(G) for G in aug.Gbar) or any(np.any(G) for G in aug.Gfbar) or aug.Mbar[0].shape[1]:
        checks["theorem"] = 5
        for a, b in ((lmi.key, lmi.theorem5) for lmi in LMIS.values() if lmi.theorem5):
            for key, src in (("lmi_max_eig", lm_bal), ("lmi_roundoff", roundoff_bal), ("lmi_raw_max_eig", lm),
                             ("lmi_raw_roundoff", roundoff), ("lmi_balanced_max_eig", lm_bal),
                             ("lmi_balanced_roundoff", roundoff_bal)):  # fmt: skip
                checks[key][b] = src[a]
    else:
        checks["theorem"] = 3
    checks["certified_by"] = certified_by(checks)
    return checks


def _holds(checks: dict, key: str) -> bool:
    lam = checks["lmi_max_eig"].get(key)
    return lam is not None and lam < -checks.get("lmi_roundoff", {}).get(key, 0.0)


def _offered(checks: dict, route: str) -> bool:
    """Can ``route`` certify the design of ``checks``? Theorem 1's only where the design holds its point P29."""
    return route != THEOREM1 or "P29_min_eig" in checks


def certified_by(checks: dict) -> str | None:
    """The first certificate (:func:`~._lmis.routes`, in the order registered) whose every LMI holds in ``checks``,
    or None. Theorem 1's counts only for a design that holds its own point, ``P29`` (``P29_min_eig`` in ``checks``):
    a design made by (45)-(46) is judged by them, as it always was, and (29) at ``P = X^-1`` (which they imply) is
    reported beside them, not relied on. Documents older than the routes have Theorem 3's only."""
    for route, keys in routes().items():
        if _offered(checks, route) and all(_holds(checks, k) for k in keys):
            return route
    return None


@dataclass(frozen=True)
class Failure:
    """One certificate item that does not hold: ``item`` is a registered LMI's key (``"45"``, ...) or ``"X"``,
    ``"Pbar"``, ``"R"``, ``"closed_loop"``, ``"discrete"``; ``text`` says it with its number."""

    item: str
    text: str


def failed(checks: dict) -> list[Failure]:
    """The certificate items that do not hold (empty: certified), as records read by field.

    The one decision of "certified", wherever a design is judged (made, loaded, simulated, generated, tuned):
    each registered LMI holds iff its balanced largest eigenvalue ``lmi_max_eig`` is below minus its round-off
    bound ``lmi_roundoff`` (:func:`certificate`), so that a recomputation on another machine, which moves it by
    less than that bound, keeps its sign."""
    bad = []
    theorem = checks.get("theorem")
    roundoff = checks.get("lmi_roundoff", {})
    # the LMIs of one certificate (route) need not hold where another's all do: (45)-(46), else (29)
    held = certified_by(checks)
    for k, lmi in LMIS.items():
        if lmi.route and (held is not None or not _offered(checks, lmi.route)):
            continue
        v = lmi.name(theorem)
        if k not in checks["lmi_max_eig"]:
            bad.append(Failure(k, f"{v} (not in the certificate)"))
            continue
        lam, eps = checks["lmi_max_eig"][k], roundoff.get(k, 0.0)
        if lam < -eps:
            continue
        if not lam < 0:
            bad.append(Failure(k, f"{v} (largest eigenvalue {lam:+.3g}, balanced; it must be negative)"))
        else:
            bad.append(Failure(
                k, f"{v} (largest eigenvalue {lam:.3g}, balanced, is within the round-off {eps:.3g} of its matrix)"
            ))  # fmt: skip
    if not checks["X_min_eig"] > 0:
        bad.append(Failure("X", f"X > 0 (smallest eigenvalue {checks['X_min_eig']:.3g})"))
    if not checks["Pbar_min_eig"] > 0:
        bad.append(Failure("Pbar", f"Pbar > 0 (smallest eigenvalue {checks['Pbar_min_eig']:.3g})"))
    if "P29_min_eig" in checks and not checks["P29_min_eig"] > 0:
        bad.append(Failure("P29", f"P29 > 0 (smallest eigenvalue {checks['P29_min_eig']:.3g})"))
    if not checks["R_max_real_eig"] < 0:
        bad.append(Failure("R", f"R_i Hurwitz (largest real part {checks['R_max_real_eig']:.3g})"))
    if not checks["closed_loop_max_real_eig"] < 0:
        bad.append(Failure(
            "closed_loop", f"A_i + B_i K_j Hurwitz (largest real part {checks['closed_loop_max_real_eig']:.3g})"
        ))  # fmt: skip
    disc = checks.get("discrete")
    if disc is not None and not disc["holds"]:
        bad.append(Failure("discrete", f"the discrete step at Ts = {disc['sample_time']:g} (Pbar decreases only for "
                           f"Ts < {disc['ts_max_lyapunov']:.3g})"))  # fmt: skip
    return bad


def failures(checks: dict) -> list[str]:
    """The texts of :func:`failed`: the certificate items that do not hold (empty: certified)."""
    return [f.text for f in failed(checks)]
