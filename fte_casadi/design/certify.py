"""A-posteriori certificates: every LMI rebuilt with numpy at the returned point.

Nothing here touches cvxpy: the left sides of (45)/(78), (46)/(79), (55)/(80) and (64)/(81)
are assembled again from the plain matrices (X, Y_j = K_j X, P, Pbar, Q_i, N, theta), so a
solver that reports "optimal" at a point where an LMI does not hold is caught.

The builders are written once for Theorem 5 (diffusion ``W_i x + G_i u + Gf_i f + M_i d2``);
with ``G = Gf = 0`` and no ``d2`` they are exactly (45), (46) of Theorem 3. Corrections of the
printed formulas (docs/method.md, "The paper's misprints"): block (1,4) of (45)/(78) is ``Bd_i`` (not ``P Bd_i``);
``Psi = A X + X A^T + B Y + Y^T B^T + sigma I``; block (3,3) of (45) is ``-I_p``. In (79) the
term ``(Wbar_i + Gbar_i K_j)^T T^T Pbar T Gbar_eij`` of Theta_13 enters with a minus sign: it
is the cross term of the error diffusion ``T (Wbar + Gbar K) x - T Gbar_e e``, exactly like
``-(W_i + G_i K_j)^T P G_eij`` beside it (the paper prints ``+``).

The same builders pose the LMIs for the solver (:mod:`fte_casadi.design.conditioned`): there the
unknowns are scaled (``X = X'/s``, ``Pbar = Pt/s``) and every term free of the unknowns is
multiplied by ``const = s``, which is ``s`` times the printed LMI at the unscaled point. With the
default ``const = 1`` they are the printed LMIs, which is what the certificate evaluates.
"""

from __future__ import annotations

import numpy as np

from .augment import Augmented
from .linalg import sym as _sym

__all__ = ["lmi45", "lmi46", "lmi45_kron", "lmi46_kron", "sliding_kron", "lmi55", "lmi64", "sliding_mismatch", "diffusion_coupling", "certificate", "ts_max",
           "lyapunov_ts_max", "discrete_certificate", "balanced",
           "block_sizes", "failures"]  # fmt: skip


def _parts(aug: Augmented, i: int):
    n, lf = aug.n, aug.lf
    A = aug.Abar[i][:n, :n]
    B = aug.Bbar[i][:n]
    Bf = aug.Abar[i][:n, n + lf :]
    W = aug.Wbar[i][:n]
    G = aug.Gbar[i][:n]
    Gf = aug.Gfbar[i][:n]
    M = aug.Mbar[i][:n]
    return A, B, Bf, W, G, Gf, M


def lmi45(
    aug: Augmented, i: int, X: np.ndarray, Y: np.ndarray, sigma: float, gamma: float, gamma1: float, const=1.0
):
    """Left side of (45) (and (78) when G_i != 0) for rule i and gain Y = Y_j.

    ``const`` multiplies every term that involves neither X nor Y (see the module docstring).
    """
    n, p, ld = aug.n, aug.p, aug.ld
    A, B, _, W, G, _, _ = _parts(aug, i)
    C = aug.Cbar[:, :n]
    Bd = aug.Bdbar[i][:n]
    Psi = A @ X + X @ A.T + B @ Y + Y.T @ B.T + const * sigma * np.eye(n)
    XW = X @ W.T + Y.T @ G.T
    Z = np.zeros
    L = np.block([
        [Psi, XW, X @ C.T, const * Bd],
        [XW.T, -X, Z((n, p)), Z((n, ld))],
        [C @ X, Z((p, n)), -const * np.eye(p), Z((p, ld))],
        [const * Bd.T, Z((ld, n)), Z((ld, p)), const * (gamma1**2 - gamma**2) * np.eye(ld)],
    ])  # fmt: skip
    return _sym(L)


def _selector(sizes, which: int) -> np.ndarray:
    """``E`` with ``E @ [z_0; z_1; ...] = z_which`` for blocks of ``sizes``."""
    E = np.zeros((sizes[which], sum(sizes)))
    a = sum(sizes[:which])
    E[:, a : a + sizes[which]] = np.eye(sizes[which])
    return E


def lmi45_kron(aug: Augmented, i: int):
    """How X enters (45) for rule i: pairs ``(U, V)`` meaning ``U^T X V + V^T X U`` (:meth:`~fte_casadi.design.sdp.Kron.of`):
    ``A X + X A^T`` and ``X W^T`` and ``X C^T`` in the first block row, ``-X`` in the second diagonal block."""
    n, p, ld = aug.n, aug.p, aug.ld
    A, _, _, W, _, _, _ = _parts(aug, i)
    C = aug.Cbar[:, :n]
    sizes = (n, n, p, ld)
    E1, E2, E3 = (_selector(sizes, b) for b in range(3))
    return [(E1, A.T @ E1 + W.T @ E2 + C.T @ E3), (E2, -0.5 * E2)]


def lmi46_kron(aug: Augmented, i: int, K: np.ndarray, T: np.ndarray):
    """How Pbar enters (46)/(79) for rule i (blocks x, d, e, d2; :func:`lmi45_kron`; ``(U, None)`` is
    ``U^T Pbar U``): ``Phi^T T^T Pbar T Phi`` with ``Phi = [Wbk, 0, -Gbe, Mb]`` and
    ``Pbar T Abar_i + Abar_i^T T^T Pbar`` in the e block (the decay term ``2 alpha Pbar`` is ``(Ee, alpha Ee)``)."""
    t = lmi46_terms(aug, i, K)
    n, ld, nbar, l2 = aug.n, aug.ld, aug.nbar, t["Mb"].shape[1]
    Ee = _selector((n, ld, nbar, l2), 2)
    Phi = np.hstack([t["Wbk"], np.zeros((nbar, ld)), -t["Gbe"], t["Mb"]])
    TPhi = T @ Phi
    return [(TPhi, None), (Ee, T @ aug.Abar[i] @ Ee)]


def sliding_kron(aug: Augmented, T: np.ndarray, right: np.ndarray):
    """How Pbar enters ``[[-tau I, E^T], [E, -tau I]]`` with ``E = Js^T T^T Pbar right`` (:func:`lmi45_kron`):
    (55) with ``right = I - Cbar^+ Cbar`` (N eliminated), (64) with ``right = T Wbar_i``."""
    a, b = right.shape[1], aug.ns
    return [(T @ aug.Js @ _selector((a, b), 1), right @ _selector((a, b), 0))]


def lmi46_terms(aug: Augmented, i: int, K: np.ndarray):
    """The constant pieces of (46)/(79) for rule i, gain K = K_j (everything but Pbar and Q_i)."""
    n, lf = aug.n, aug.lf
    _, B, Bf, W, G, Gf, M = _parts(aug, i)
    J0, J2 = aug.J0, aug.J2
    De = aug.Cbar[:, n + lf :] @ J2
    Be = B @ K @ J0 - Bf @ J2
    Ge = G @ K @ J0 - Gf @ J2
    Wk = W + G @ K
    Wbk = aug.Wbar[i] + aug.Gbar[i] @ K
    Gbe = aug.Gbar[i] @ K @ J0 - aug.Gfbar[i] @ J2
    return dict(De=De, Be=Be, Ge=Ge, Wk=Wk, Wbk=Wbk, Gbe=Gbe, M=M, Mb=aug.Mbar[i], C=aug.Cbar[:, :n])


def lmi46(aug, i, K, P, T, Pbar, Q, sigma, gamma1, gamma2=1.0, alpha=0.0, const=1.0):
    """Left side of (46) (Theorem 3) or (79) (Theorem 5) for rule i, gain K_j, observer Q_i.

    ``alpha > 0`` adds the decay-rate term ``2 alpha Pbar`` to the (3,3) block (the
    conditioned variant's design constraint); the recorded certificate uses ``alpha = 0``.
    ``const`` multiplies every term that involves neither Pbar nor Q (module docstring).
    """
    t = lmi46_terms(aug, i, K)
    Ab, Cb = aug.Abar[i], aug.Cbar
    TPT = T.T @ Pbar @ T
    C, De, Be, Ge, Wk, Wbk, Gbe, M, Mb = (
        t[k] for k in ("C", "De", "Be", "Ge", "Wk", "Wbk", "Gbe", "M", "Mb")
    )
    n, ld, nbar, l2 = aug.n, aug.ld, aug.nbar, M.shape[1]
    T11 = -const * sigma * P @ P + Wbk.T @ TPT @ Wbk
    T13 = const * (-P @ Be - Wk.T @ P @ Ge + C.T @ De) - Wbk.T @ TPT @ Gbe
    T33 = (
        Pbar @ T @ Ab
        + Ab.T @ T.T @ Pbar
        - Q @ Cb
        - Cb.T @ Q.T
        + const * (Ge.T @ P @ Ge + De.T @ De)
        + Gbe.T @ TPT @ Gbe
    )
    T33 = T33 + 2 * alpha * Pbar
    Z = np.zeros
    rows = [
        [T11, Z((n, ld)), T13],
        [Z((ld, n)), -const * (gamma1**2) * np.eye(ld), Z((ld, nbar))],
        [T13.T, Z((nbar, ld)), T33],
    ]
    if l2:
        T14 = const * (Wk.T @ P @ M) + Wbk.T @ TPT @ Mb
        T34 = -const * (Ge.T @ P @ M) - Gbe.T @ TPT @ Mb
        T44 = const * (M.T @ P @ M - gamma2**2 * np.eye(l2)) + Mb.T @ TPT @ Mb
        rows[0].append(T14)
        rows[1].append(Z((ld, l2)))
        rows[2].append(T34)
        rows.append([T14.T, Z((l2, ld)), T34.T, T44])
    return _sym(np.block(rows))


def sliding_mismatch(aug: Augmented, T: np.ndarray, Pbar: np.ndarray, N: np.ndarray) -> np.ndarray:
    """``J1^T T^T Pbar - N Cbar``: how far the sliding surface (20) is from holding (the E of (55)).

    With Remark 5, ``J1`` is ``[Bdbar_u J1]`` (:attr:`~fte_casadi.design.augment.Augmented.Js`)."""
    return aug.Js.T @ T.T @ Pbar - N @ aug.Cbar


def diffusion_coupling(aug: Augmented, i: int, T: np.ndarray, Pbar: np.ndarray) -> np.ndarray:
    """``J1^T T^T Pbar T Wbar_i``: the diffusion seen by the sliding variable (the E of (64));
    ``[Bdbar_u J1]`` in place of ``J1`` with Remark 5."""
    return aug.Js.T @ T.T @ Pbar @ T @ aug.Wbar[i]


def lmi55(aug: Augmented, T: np.ndarray, Pbar: np.ndarray, N: np.ndarray, theta: float):
    E = sliding_mismatch(aug, T, Pbar, N)
    return _sym(np.block([[-theta * np.eye(aug.nbar), E.T], [E, -np.eye(aug.ns)]]))


def lmi64(aug: Augmented, i: int, T: np.ndarray, Pbar: np.ndarray, theta: float):
    E = diffusion_coupling(aug, i, T, Pbar)
    return _sym(np.block([[-theta * np.eye(aug.n), E.T], [E, -np.eye(aug.ns)]]))


def block_sizes(aug: Augmented) -> dict:
    l2 = aug.Mbar[0].shape[1]
    return {
        "45": [aug.n, aug.n, aug.p, aug.ld],
        "46": [aug.n, aug.ld, aug.nbar] + ([l2] if l2 else []),
        "55": [aug.nbar, aug.ns],
        "64": [aug.n, aug.ns],
    }


def theta_lmi_max_eig(L: np.ndarray, a: int) -> float:
    """The largest eigenvalue of ``[[-theta I_a, E^T], [E, -I_b]]`` ((55), (64)), exactly from the singular
    values s of E: ``2 (s^2 - theta) / ((theta + 1) + sqrt((theta - 1)^2 + 4 s^2))`` (and ``-theta``, ``-1``
    for the directions E does not couple). eigvalsh loses it when theta is large: a plant measured in mm has
    theta of order 1e16-1e23 beside the ``-I`` block, and the eigenvalue near -1 drowns in round-off of
    theta's size (it came out as +1e-8 for a design whose (55) holds with margin)."""
    theta = float(-L[0, 0])
    E = L[a:, :a]
    sv = np.linalg.svd(E, compute_uv=False) if E.size else np.zeros(0)
    cand = [2.0 * (x * x - theta) / ((theta + 1.0) + np.hypot(theta - 1.0, 2.0 * x)) for x in sv]
    if a > len(sv):
        cand.append(-theta)
    if L.shape[0] - a > len(sv):
        cand.append(-1.0)
    return float(max(cand))


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


def distinct(K) -> list[int]:
    """The indices of the distinct gains among ``K_1..K_r`` (the first of equal ones): a pair (i, j) with
    ``K_j`` equal to an earlier ``K_j'`` gives the very same matrices as (i, j'), so it is checked once
    (the conditioned design has one common gain: r checks instead of r^2, 64 rules: 64 instead of 4096)."""
    out: list[int] = []
    for j, Kj in enumerate(K):
        if not any(np.array_equal(Kj, K[k]) for k in out):
            out.append(j)
    return out


def lmi_matrices(aug, d: dict, params: dict):
    """Yield ``(key, matrix)`` for every LMI of the design at the point ``d``: (45) and (46) for
    every rule pair, (64) for every rule, (55) once. Each must be negative definite."""
    X, K, P, T, Pbar, Q, N, theta = (d[k] for k in ("X", "K", "P", "T", "Pbar", "Q", "N", "theta"))
    s, g, g1, g2 = params["sigma"], params["gamma"], params["gamma1"], params.get("gamma2", params["gamma"])
    js = distinct(K)
    for i in range(aug.r):
        for j in js:
            yield "45", lmi45(aug, i, X, K[j] @ X, s, g, g1)
            yield "46", lmi46(aug, i, K[j], P, T, Pbar, Q[i], s, g1, g2)
        yield "64", lmi64(aug, i, T, Pbar, theta)
    yield "55", lmi55(aug, T, Pbar, N, theta)


def certificate(aug, d: dict, params: dict) -> dict:
    """Recompute every LMI at the design point ``d`` (X, K, P, T, Pbar, Q, N, theta, R, L1).

    Returns the ``checks`` dictionary of the design document.
    """
    X, K, Pbar, theta = d["X"], d["K"], d["Pbar"], d["theta"]
    sizes = block_sizes(aug)
    lm = {"45": -np.inf, "46": -np.inf, "55": -np.inf, "64": -np.inf}
    blocks = {k: [-np.inf] * len(v) for k, v in sizes.items()}
    roundoff = dict.fromkeys(lm, 0.0)
    lm_bal, roundoff_bal = dict(lm), dict(roundoff)
    for key, L in lmi_matrices(aug, d, params):
        top = theta_lmi_max_eig(L, sizes[key][0]) if key in ("55", "64") else _maxeig(L)
        lm[key] = max(lm[key], top)
        roundoff[key] = max(roundoff[key], eig_roundoff(L))
        Lb = balanced(L)
        lm_bal[key] = max(lm_bal[key], _maxeig(Lb))
        roundoff_bal[key] = max(roundoff_bal[key], eig_roundoff(Lb))
        blocks[key] = [max(a, b) for a, b in zip(blocks[key], _block_max(L, sizes[key]))]
    r, js = aug.r, distinct(K)
    cl = max(float(np.max(np.linalg.eigvals(aug.Abar[i][: aug.n, : aug.n] + aug.Bbar[i][: aug.n] @ K[j]).real))
             for i in range(r) for j in js)  # fmt: skip
    R = d["R"]
    ev_P = np.linalg.eigvalsh(_sym(Pbar))
    ev_X = np.linalg.eigvalsh(_sym(X))
    checks = {
        "lmi_max_eig": dict(lm),
        "lmi_block_max_eig": blocks,
        "lmi_roundoff": roundoff,
        "lmi_balanced_max_eig": lm_bal,
        "lmi_balanced_roundoff": roundoff_bal,
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
    if any(np.any(G) for G in aug.Gbar) or any(np.any(G) for G in aug.Gfbar) or aug.Mbar[0].shape[1]:
        checks["theorem"] = 5
        for a, b in (("45", "78"), ("46", "79"), ("55", "80"), ("64", "81")):
            checks["lmi_max_eig"][b] = lm[a]
            checks["lmi_roundoff"][b] = roundoff[a]
            checks["lmi_balanced_max_eig"][b] = lm_bal[a]
            checks["lmi_balanced_roundoff"][b] = roundoff_bal[a]
    else:
        checks["theorem"] = 3
    return checks


def failures(checks: dict) -> list[str]:
    """Names of the certificate items that do not hold (empty: certified)."""
    bad = []
    names = {"45": "LMI (45)", "46": "LMI (46)", "55": "LMI (55)", "64": "LMI (64)"}
    if checks.get("theorem") == 5:
        names = {"45": "LMI (78)", "46": "LMI (79)", "55": "LMI (80)", "64": "LMI (81)"}
    roundoff = checks.get("lmi_roundoff", {})
    bal, bal_eps = checks.get("lmi_balanced_max_eig", {}), checks.get("lmi_balanced_roundoff", {})
    for k, v in names.items():
        lam, eps = checks["lmi_max_eig"][k], roundoff.get(k, 0.0)
        # the sign is certain when the margin exceeds the round-off of the matrix as computed, or of its
        # balanced form D L D (the same definiteness; see balanced())
        beyond = lam < -eps or (k in bal and bal[k] < -bal_eps.get(k, 0.0))
        if beyond:
            continue
        if not lam < 0:
            bad.append(f"{v} (largest eigenvalue {lam:.3g})")
        else:
            bad.append(f"{v} (largest eigenvalue {lam:.3g} is within the round-off {eps:.3g} of its matrix"
                       + (f", and {bal[k]:.3g} of its balanced form within {bal_eps.get(k, 0.0):.3g}" if k in bal else "")
                       + ")")  # fmt: skip
    if not checks["X_min_eig"] > 0:
        bad.append(f"X > 0 (smallest eigenvalue {checks['X_min_eig']:.3g})")
    if not checks["Pbar_min_eig"] > 0:
        bad.append(f"Pbar > 0 (smallest eigenvalue {checks['Pbar_min_eig']:.3g})")
    if not checks["R_max_real_eig"] < 0:
        bad.append(f"R_i Hurwitz (largest real part {checks['R_max_real_eig']:.3g})")
    if not checks["closed_loop_max_real_eig"] < 0:
        bad.append(f"A_i + B_i K_j Hurwitz (largest real part {checks['closed_loop_max_real_eig']:.3g})")
    disc = checks.get("discrete")
    if disc is not None and not disc["holds"]:
        bad.append(
            f"the discrete step at Ts = {disc['sample_time']:g} (Pbar decreases only for Ts < "
            f"{disc['ts_max_lyapunov']:.3g})"
        )
    return bad
