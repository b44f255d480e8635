"""The LMIs of Theorems 3 and 5: their left sides built with numpy, and the registry that names them once.

The builders are written once for Theorem 5 (diffusion ``W_i x + G_i u + Gf_i f + M_i d2``);
with ``G = Gf = 0`` and no ``d2`` they are exactly (45), (46) of Theorem 3. Corrections of the
printed formulas (docs/method.md, "The paper's misprints"): block (1,4) of (45)/(78) is ``Bd_i`` (not ``P Bd_i``);
``Psi = A X + X A^T + B Y + Y^T B^T + sigma I``; block (3,3) of (45) is ``-I_p``. In (79) the
term ``(Wbar_i + Gbar_i K_j)^T T^T Pbar T Gbar_eij`` of Theta_13 enters with a minus sign: it
is the cross term of the error diffusion ``T (Wbar + Gbar K) x - T Gbar_e e``, exactly like
``-(W_i + G_i K_j)^T P G_eij`` beside it (the paper prints ``+``).

The same builders pose the LMIs for the solver (:mod:`~fte_casadi.design.core._conditioned`,
:mod:`~fte_casadi.design.core._paper`): there the unknowns are scaled (``X = X'/s``, ``Pbar = Pt/s``) and
every term free of the unknowns is multiplied by ``const = s``, which is ``s`` times the printed LMI at the
unscaled point. With the default ``const = 1`` they are the printed LMIs, which is what the certificate
evaluates.

:data:`LMIS` registers each LMI once: its key in the design document (``checks["lmi_max_eig"]["45"]``), its
Theorem 5 number, what it certifies, its block sizes, how its left sides are built at a design point, and how it
is posed in each problem that solves for it (``pose``, by the names of :data:`PROBLEMS`; :func:`posed` gathers
them for a problem, which adds only its own scaffolding). The certificate
(:func:`~fte_casadi.design.core._certify.certificate`), its failures, the re-certification of a loaded document,
``fte design``'s summary and ``fte reproduce``'s table read it; a new LMI is one :class:`LMI` given to
:func:`register` (with its builder, and its posings where the design solves for it).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._augment import Augmented
from ._linalg import sym as _sym
from ._sdp import Layout, affine_lmi, margin_lmi

__all__ = ["LMI", "LMIS", "register", "unregister", "block_sizes", "distinct", "theta_lmi_max_eig",
           "lmi45", "lmi_decay", "lmi_decay_kron", "loop_decay", "lmi46", "lmi55", "lmi64", "lmi45_kron", "lmi46_kron", "lmi46_terms", "sliding_kron",
           "sliding_mismatch", "diffusion_coupling", "lmi29", "routes", "THEOREM3", "THEOREM1", "Posed", "Posing", "posed",
           "PROBLEMS", "STEP3", "STEP5", "JOINT", "PAPER3", "PAPER5", "STRICT", "balanced", "balanced_margin",
           "diag_blocks"]  # fmt: skip


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
    """How X enters (45) for rule i: pairs ``(U, V)`` meaning ``U^T X V + V^T X U`` (:meth:`~fte_casadi.design.core._sdp.Kron.of`):
    ``A X + X A^T`` and ``X W^T`` and ``X C^T`` in the first block row, ``-X`` in the second diagonal block."""
    n, p, ld = aug.n, aug.p, aug.ld
    A, _, _, W, _, _, _ = _parts(aug, i)
    C = aug.Cbar[:, :n]
    sizes = (n, n, p, ld)
    E1, E2, E3 = (_selector(sizes, b) for b in range(3))
    return [(E1, A.T @ E1 + W.T @ E2 + C.T @ E3), (E2, -0.5 * E2)]


def lmi_decay(aug: Augmented, i: int, X: np.ndarray, Y: np.ndarray, beta: float) -> np.ndarray:
    """Left side of the closed loop's decay-rate LMI for rule i and gain ``Y = Y_j``:
    ``A_i X + X A_i^T + B_i Y + Y^T B_i^T + 2 beta X``. With X common to the rules (and to (45)), negative for
    every rule means ``V = x^T X^-1 x`` decreases at least as ``exp(-2 beta t)`` along ``xdot = (A(h) + B(h) K)
    x`` for ANY blending ``h`` of the rules: the loop decays at least at ``beta`` (no noise, no d). Not in the
    paper: the conditioned variant's requirement on the controller, as ``alpha`` is on the observer."""
    A, B = aug.Abar[i][: aug.n, : aug.n], aug.Bbar[i][: aug.n]
    return _sym(A @ X + X @ A.T + B @ Y + Y.T @ B.T + 2 * beta * X)


def lmi_decay_kron(aug: Augmented, i: int, beta: float):
    """How X enters :func:`lmi_decay` (:func:`lmi45_kron`): ``(A_i + beta I) X + X (A_i + beta I)^T``."""
    A = aug.Abar[i][: aug.n, : aug.n]
    return [(np.eye(aug.n), A.T + beta * np.eye(aug.n))]


def loop_decay(aug: Augmented, X: np.ndarray, K) -> float:
    """The largest ``beta`` for which :func:`lmi_decay` holds at ``(X, K_j)`` for every rule and gain: the decay
    rate of the closed loop that X certifies for any blending of the rules, exactly,
    ``min_ij lambda_min(X^-1/2 (-(A_i + B_i K_j) X - X (A_i + B_i K_j)^T) X^-1/2) / 2`` (negative: not even
    stable with this X)."""
    Xs = _sym(X)
    w, V = np.linalg.eigh(Xs)
    Xi = (V / np.sqrt(w)) @ V.T
    best = np.inf
    for i in range(aug.r):
        for j in distinct(K):
            M = lmi_decay(aug, i, Xs, K[j] @ Xs, 0.0)
            best = min(best, -0.5 * float(np.linalg.eigvalsh(_sym(Xi @ M @ Xi))[-1]))
    return float(best)


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


def lmi29(aug, i, K, P1, T, Pbar, Q, gamma, gamma2=1.0, alpha=0.0, const=1.0):
    """Left side of Theorem 1's (29) for rule i, gain ``K = K_j``, observer ``Q_i``: the closed loop (27) with the
    Lyapunov function ``V = x^T P1 x + e^T Pbar e``, in blocks ``x, d, e`` (and ``d2``), without Theorem 2's split
    of its x block into ``-sigma P^2`` and (41). With the diffusion of Theorem 5 (``(W_i + G_i K) x - G_ei e +
    M_i d2`` in x, ``T`` times the augmented one in e; :func:`lmi46_terms`)::

        11: P1 (A_i + B_i K) + (A_i + B_i K)^T P1 + Wk^T P1 Wk + Wbk^T T^T Pbar T Wbk + C^T C
        12: P1 Bd_i        13: -P1 Be_ij - Wk^T P1 Ge_ij - Wbk^T T^T Pbar T Gbe_ij + C^T De
        22: -gamma^2 I     33: Phi_i33 + Ge_ij^T P1 Ge_ij + Gbe_ij^T T^T Pbar T Gbe_ij  (+ 2 alpha Pbar)

    (and the d2 row as in (79)). It is linear in ``(P1, Pbar, Q_i)`` at a fixed K. At ``P1 = X^-1`` it is the sum of
    (46) and (45) before its congruence (Theorem 2's proof, (44)), so (45) and (46) imply it; it also holds where
    they do not. ``const`` multiplies every term free of P1, Pbar and Q (the module docstring)."""
    t = lmi46_terms(aug, i, K)
    A, B, _, _, _, _, _ = _parts(aug, i)
    Bd = aug.Bdbar[i][: aug.n]
    Ab, Cb = aug.Abar[i], aug.Cbar
    TPT = T.T @ Pbar @ T
    C, De, Be, Ge, Wk, Wbk, Gbe, M, Mb = (
        t[k] for k in ("C", "De", "Be", "Ge", "Wk", "Wbk", "Gbe", "M", "Mb")
    )
    ld, nbar, l2 = aug.ld, aug.nbar, M.shape[1]
    Acl = A + B @ K
    T11 = P1 @ Acl + Acl.T @ P1 + Wk.T @ P1 @ Wk + Wbk.T @ TPT @ Wbk + const * C.T @ C
    T13 = -P1 @ Be - Wk.T @ P1 @ Ge - Wbk.T @ TPT @ Gbe + const * C.T @ De
    T33 = (Pbar @ T @ Ab + Ab.T @ T.T @ Pbar - Q @ Cb - Cb.T @ Q.T + Ge.T @ P1 @ Ge + Gbe.T @ TPT @ Gbe
           + const * De.T @ De + 2 * alpha * Pbar)  # fmt: skip
    Z = np.zeros
    rows = [
        [T11, P1 @ Bd, T13],
        [Bd.T @ P1, -const * gamma**2 * np.eye(ld), Z((ld, nbar))],
        [T13.T, Z((nbar, ld)), T33],
    ]
    if l2:
        T14 = Wk.T @ P1 @ M + Wbk.T @ TPT @ Mb
        T34 = -Ge.T @ P1 @ M - Gbe.T @ TPT @ Mb
        T44 = M.T @ P1 @ M + Mb.T @ TPT @ Mb - const * gamma2**2 * np.eye(l2)
        rows[0].append(T14)
        rows[1].append(Z((ld, l2)))
        rows[2].append(T34)
        rows.append([T14.T, Z((l2, ld)), T34.T, T44])
    return _sym(np.block(rows))


def sliding_mismatch(aug: Augmented, T: np.ndarray, Pbar: np.ndarray, N: np.ndarray) -> np.ndarray:
    """``J1^T T^T Pbar - N Cbar``: how far the sliding surface (20) is from holding (the E of (55)).

    With Remark 5, ``J1`` is ``[Bdbar_u J1]`` (:attr:`~fte_casadi.design._augment.Augmented.Js`)."""
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


def distinct(K) -> list[int]:
    """The indices of the distinct gains among ``K_1..K_r`` (the first of equal ones): a pair (i, j) with
    ``K_j`` equal to an earlier ``K_j'`` gives the very same matrices as (i, j'), so it is checked once
    (the conditioned design has one common gain: r checks instead of r^2, 64 rules: 64 instead of 4096)."""
    out: list[int] = []
    for j, Kj in enumerate(K):
        if not any(np.array_equal(Kj, K[k]) for k in out):
            out.append(j)
    return out


# -- how the LMIs are posed -------------------------------------------------------------------------------

#: the problems that solve for the registered LMIs, by the name an LMI's ``pose`` uses: the conditioned
#: variant's step 3 (X', Y', s, t) and step 5 by (46) (Pt, s, rho, tau) or by Theorem 1's (29) (Pt, P1, s, rho,
#: tau) (:mod:`._conditioned`, :mod:`._step5`), and the paper variant's two solves as printed (:mod:`._paper`)
STEP3, STEP5, JOINT, PAPER3, PAPER5 = "step 3", "step 5", "step 5 by (29)", "paper step 3", "paper step 5"
PROBLEMS = (STEP3, STEP5, JOINT, PAPER3, PAPER5)
#: the paper variant's strict LMIs are imposed as ``<= -STRICT I``
STRICT = 1e-7


@dataclass(frozen=True)
class Posed:
    """What a problem gives the LMIs it poses: the augmented plant, the design's parameters, the problem's
    unknowns (``layout``) and what is fixed there: the input scaling ``Su`` (step 3), the loop's gain ``K``
    (one matrix, or the paper's list of ``K_j``), ``T`` and step 3's ``X`` (step 5)."""

    aug: Augmented
    params: dict
    layout: Layout
    Su: np.ndarray | None = None
    K: Any = None
    T: np.ndarray | None = None
    X: np.ndarray | None = None


@dataclass(frozen=True)
class Posing:
    """How one LMI is posed in one problem: ``build(posed)`` returns its constraints there (``MarginLMI`` in the
    conditioned variant, ``AffineLMI`` in the paper's; none when it does not apply, e.g. no decay rate asked);
    ``part``: ``"feasibility"`` (in the solve that finds a first point) or ``"rest"`` (added after it: step 5's
    (55), (64)); ``soft``: relaxed by phase 1's slack (step 3's (45) and the decay LMI), posed before the hard
    ones."""

    build: Callable[[Posed], list]
    part: str = "feasibility"
    soft: bool = False


def posed(problem: str, at: Posed, part: str = "feasibility") -> list:
    """The constraints of every registered LMI posed in ``problem`` (its ``pose``) for ``part``, in the order
    registered, the soft ones first."""
    if problem not in PROBLEMS:
        raise ValueError(f"no problem {problem!r}; the problems are {', '.join(PROBLEMS)}")
    chosen = [e.pose[problem] for e in LMIS.values() if problem in e.pose and e.pose[problem].part == part]
    return [L for p in chosen if p.soft for L in p.build(at)] + [
        L for p in chosen if not p.soft for L in p.build(at)
    ]


def diag_blocks(sizes, values) -> np.ndarray:
    """The block-diagonal matrix with ``values[k] I`` in a block of ``sizes[k]``."""
    return np.diag(np.concatenate([np.full(k, float(v)) for k, v in zip(sizes, values)]))


def balanced(E: np.ndarray, tau) -> np.ndarray:
    """``[[-tau I, E^T], [E, -tau I]] <= 0``, i.e. ``||E||_2 <= tau``."""
    a, b = E.shape[1], E.shape[0]
    return np.block([[-tau * np.eye(a), E.T], [E, -tau * np.eye(b)]])


def balanced_margin(tau, a: int, b: int) -> np.ndarray:
    """The relative margin of :func:`balanced`: ``||E||_2 <= (1 - m) tau``."""
    return tau * np.eye(a + b)


def _pose45(at: Posed) -> list:
    """(45) per rule in ``(X', Y', s, t)``, one common gain ``K = Su Y' X'^-1``; margin relative to each block."""
    aug, lay, Su = at.aug, at.layout, at.Su
    sg, g, g1 = at.params["sigma"], at.params["gamma"], at.params["gamma1"]
    D = diag_blocks([aug.n, aug.n, aug.p, aug.ld], [sg, 0.0, 1.0, g**2 - g1**2])
    return [margin_lmi(f"(45) rule {i + 1}", lay, lambda X, Y, s, t, i=i: lmi45(aug, i, X, Su @ Y, sg, g, g1, const=s),
                       margin=lambda X, Y, s, t: s * D, support=lay.support("X", "Y", "s"),
                       kron=("X", lmi45_kron(aug, i)))
            for i in range(aug.r)]  # fmt: skip


def _pose_decay(at: Posed) -> list:
    """The decay LMI per rule where a rate is asked (``params["beta"] > 0``): homogeneous in ``(X', Y')``, its
    margin relative to the rate, ``<= -2 beta m I`` (``X' >= I``)."""
    aug, lay, Su = at.aug, at.layout, at.Su
    beta = float(at.params.get("beta", 0.0))
    if beta <= 0:
        return []
    eye = np.eye(aug.n)
    return [margin_lmi(f"decay rule {i + 1}", lay, lambda X, Y, s, t, i=i: lmi_decay(aug, i, X, Su @ Y, beta),
                       margin=lambda X, Y, s, t: 2 * beta * eye, support=lay.support("X", "Y"),
                       kron=("X", lmi_decay_kron(aug, i, beta)))
            for i in range(aug.r)]  # fmt: skip


def _pose46(at: Posed) -> list:
    """(46) per rule in ``(Pt, s, rho, tau)`` after the congruence by ``diag(X, I)``, ``Q_i = rho_i Cbar^T / 2``,
    without its d rows (decoupled: ``-gamma1^2 s I`` holds iff ``s > 0``, which the x block demands; posed, it only
    made the problem badly scaled; the certificate keeps it); the decay term ``2 alpha Pt`` its parameter."""
    aug, lay, K, T, X = at.aug, at.layout, at.K, at.T, at.X
    n, ld, nbar, r = aug.n, aug.ld, aug.nbar, aug.r
    sg, g1 = at.params["sigma"], at.params["gamma1"]
    g2 = at.params.get("gamma2", at.params["gamma"])
    P = np.linalg.inv(X)
    Cb = aug.Cbar
    l2 = aug.Mbar[0].shape[1]
    k = n + ld + nbar + l2
    Dx = np.eye(k)
    Dx[:n, :n] = X
    keep = np.r_[0:n, n + ld : k]
    sub = np.ix_(keep, keep)

    def b46(i):
        def f(Pt, s, rho, tau):
            return (Dx @ lmi46(aug, i, K, P, T, Pt, rho[i] * Cb.T / 2, sg, g1, g2, const=s) @ Dx)[sub]

        return f

    def m46(Pt, s, rho, tau):
        return diag_blocks([n, nbar, l2], [sg * s, 1.0, g2**2 * s])

    def decay(Pt, s, rho, tau):
        M = np.zeros((n + nbar + l2, n + nbar + l2))
        M[n : n + nbar, n : n + nbar] = 2 * Pt
        return M

    def k46(i):  # the Kron terms of (46) after the congruence by Dx, without the d rows
        return "Pt", [
            (U @ Dx[:, keep], None if V is None else V @ Dx[:, keep]) for U, V in lmi46_kron(aug, i, K, T)
        ]

    Ee = np.eye(k)[n + ld : n + ld + nbar][:, keep]
    return [margin_lmi(f"(46) rule {i + 1}", lay, b46(i), decay, m46, support=lay.support("Pt", "s", ("rho", i)),
                       kron=k46(i), kron_param=("Pt", [(Ee, Ee)]))
            for i in range(r)]  # fmt: skip


def _pose29(at: Posed) -> list:
    """Theorem 1's (29) per rule in ``(P1t, Pt, s, rho)`` (``P29 = P1t / s``, homogenised as (46)); margins per
    block: ``P1t / tau`` in x (a decay rate of the loop's part of V relative to the plant's rate ``1 / tau``),
    ``gamma^2 s`` in d, I in e, ``gamma2^2 s`` in d2; the decay term ``2 alpha Pt`` its parameter."""
    from .._augment import time_scale

    aug, lay, K, T = at.aug, at.layout, at.K, at.T
    n, ld, nbar, r = aug.n, aug.ld, aug.nbar, aug.r
    g = at.params["gamma"]
    g2 = at.params.get("gamma2", g)
    rate = 1.0 / time_scale(aug)
    l2 = aug.Mbar[0].shape[1]
    k = n + ld + nbar + l2

    def b29(i):
        def f(Pt, P1, s, rho, tau):
            return lmi29(aug, i, K, P1, T, Pt, rho[i] * aug.Cbar.T / 2, g, g2, const=s)

        return f

    def m29(Pt, P1, s, rho, tau):
        M = diag_blocks([n, ld, nbar, l2], [0.0, g**2 * s, 1.0, g2**2 * s])
        M[:n, :n] = rate * P1
        return M

    def decay(Pt, P1, s, rho, tau):
        M = np.zeros((k, k))
        M[n + ld : n + ld + nbar, n + ld : n + ld + nbar] = 2 * Pt
        return M

    Ee = np.eye(k)[n + ld : n + ld + nbar]
    return [margin_lmi(f"(29) rule {i + 1}", lay, b29(i), decay, m29,
                       support=lay.support("Pt", "P1", "s", ("rho", i)),
                       kron=("Pt", lmi46_kron(aug, i, K, T)), kron_param=("Pt", [(Ee, Ee)]))
            for i in range(r)]  # fmt: skip


def _pose55(at: Posed) -> list:
    """(55) in ``(Pt, tau)`` with N eliminated (``N = Js^T T^T Pt Cbar^+``, the exact minimiser of the mismatch),
    in the balanced form ``||E(Pt)|| <= tau``."""
    aug, lay, T = at.aug, at.layout, at.T
    nbar, lf = aug.nbar, aug.ns  # ns = lf (+ Remark 5's directions)
    Cb = aug.Cbar
    Cp = np.linalg.pinv(Cb)

    def N_of(Pt):
        return aug.Js.T @ T.T @ Pt @ Cp

    return [margin_lmi("(55)", lay, lambda Pt, tau, **_: balanced(sliding_mismatch(aug, T, Pt, N_of(Pt)), tau),
                       margin=lambda Pt, tau, **_: balanced_margin(tau, nbar, lf), support=lay.support("Pt", "tau"),
                       kron=("Pt", sliding_kron(aug, T, np.eye(nbar) - Cp @ Cb)))]  # fmt: skip


def _pose64(at: Posed) -> list:
    """(64) per rule in ``(Pt, tau)``, in the balanced form ``||E_i(Pt)|| <= tau``."""
    aug, lay, T = at.aug, at.layout, at.T
    n, lf = aug.n, aug.ns
    return [margin_lmi(f"(64) rule {i + 1}", lay,
                       lambda Pt, tau, i=i, **_: balanced(diffusion_coupling(aug, i, T, Pt), tau),
                       margin=lambda Pt, tau, **_: balanced_margin(tau, n, lf), support=lay.support("Pt", "tau"),
                       kron=("Pt", sliding_kron(aug, T, T @ aug.Wbar[i])))
            for i in range(aug.r)]  # fmt: skip


def _paper45(at: Posed) -> list:
    """(45) as printed for every rule i and gain ``Y_j`` (the paper's one gain per rule), ``<= -STRICT I``."""
    aug, p = at.aug, at.params
    sg, g, g1, r = p["sigma"], p["gamma"], p["gamma1"], aug.r
    k = 2 * aug.n + aug.p + aug.ld
    return [affine_lmi(f"(45) rule {i + 1}, gain {j + 1}", at.layout,
                       lambda i=i, j=j, **u: lmi45(aug, i, u["X"], u[f"Y{j}"], sg, g, g1) + STRICT * np.eye(k))
            for i in range(r) for j in range(r)]  # fmt: skip


def _paper46(at: Posed) -> list:
    """(46) as printed for every rule i and gain ``K_j`` at ``P = X^-1``, ``Q_i`` free, ``<= -STRICT I``."""
    aug, p, K, T = at.aug, at.params, at.K, at.T
    sg, g1, g2, r = p["sigma"], p["gamma1"], p.get("gamma2", p["gamma"]), aug.r
    P = np.linalg.inv(at.X)
    k = aug.n + aug.ld + aug.nbar + aug.Mbar[0].shape[1]
    return [affine_lmi(f"(46) rule {i + 1}, gain {j + 1}", at.layout,
                       lambda i=i, j=j, **u: lmi46(aug, i, K[j], P, T, u["Pbar"], u[f"Q{i}"], sg, g1, g2) + STRICT * np.eye(k))
            for i in range(r) for j in range(r)]  # fmt: skip


def _schur(L0: np.ndarray, theta, a: int, b: int) -> np.ndarray:
    """(55)/(64) built at theta = 0, with ``-theta I`` in the first block and the strictness margin."""
    M = L0.copy()
    M[:a, :a] -= theta * np.eye(a)
    return M + STRICT * np.eye(a + b)


def _paper55(at: Posed) -> list:
    aug, T = at.aug, at.T
    return [affine_lmi("(55)", at.layout,
                       lambda **u: _schur(lmi55(aug, T, u["Pbar"], u["N"], 0.0), u["theta"], aug.nbar, aug.ns))]  # fmt: skip


def _paper64(at: Posed) -> list:
    aug, T = at.aug, at.T
    return [affine_lmi(f"(64) rule {i + 1}", at.layout,
                       lambda i=i, **u: _schur(lmi64(aug, i, T, u["Pbar"], 0.0), u["theta"], aug.n, aug.ns))
            for i in range(aug.r)]  # fmt: skip


# -- the registry -----------------------------------------------------------------------------------------


@dataclass(frozen=True)
class LMI:
    """One LMI of the design, registered once (:func:`register`).

    ``key``: its name in the design document (``checks["lmi_max_eig"][key]``) and its number as printed
    (Theorem 3); ``theorem5``: its number in Theorem 5, under which the document repeats its values (None:
    none); ``what``: what it certifies, in a few words; ``matrices(aug, point, params)``: its left sides at the
    design point (every one must be negative definite; ``point`` holds X, K, P, T, Pbar, Q, N, theta, R, L1 and
    ``params`` the design's parameters); ``blocks(aug)``: the sizes of its diagonal blocks;
    ``max_eig(L, blocks)``: its largest eigenvalue where a formula is more exact than ``eigvalsh`` (None:
    ``eigvalsh``); ``route``: "" when every certificate needs it, else the name of the certificate it belongs to
    (:func:`routes`: a design is certified when every LMI of one route holds, with those of no route)."""

    key: str
    theorem5: str | None
    what: str
    matrices: Callable[[Augmented, dict, dict], Iterable[np.ndarray]]
    blocks: Callable[[Augmented], list]
    max_eig: Callable[[np.ndarray, list], float] | None = None
    route: str = ""
    pose: Mapping[str, Posing] = field(default_factory=dict)

    def number(self, theorem: int | None = 3) -> str:
        """Its number in ``theorem`` (3 or 5): ``"45"`` or ``"78"``."""
        return self.theorem5 if theorem == 5 and self.theorem5 else self.key

    def name(self, theorem: int | None = 3) -> str:
        """Its printed name in ``theorem``: ``"LMI (45)"`` or ``"LMI (78)"``."""
        return f"LMI ({self.number(theorem)})"


#: every LMI of the design, by key, in the order they are reported (:func:`register` adds one)
LMIS: dict[str, LMI] = {}


def register(lmi: LMI) -> LMI:
    """Add ``lmi`` to :data:`LMIS` (a key already there is refused, as a problem it cannot be posed in, and a
    posing in step 3 that is not soft: phase 1 relaxes every LMI of step 3 but the normalisation); returns it."""
    if lmi.key in LMIS:
        raise ValueError(f"an LMI with the key {lmi.key!r} is registered already ({LMIS[lmi.key].what})")
    unknown = sorted(set(lmi.pose) - set(PROBLEMS))
    if unknown:
        raise ValueError(
            f"LMI {lmi.key!r} is posed in {', '.join(unknown)}: the problems are {', '.join(PROBLEMS)}"
        )
    if STEP3 in lmi.pose and not (lmi.pose[STEP3].soft and lmi.pose[STEP3].part == "feasibility"):
        raise ValueError(f"LMI {lmi.key!r}: an LMI posed in step 3 is soft and in its feasibility part")
    LMIS[lmi.key] = lmi
    return lmi


def unregister(key: str) -> None:
    """Remove the LMI ``key`` from :data:`LMIS`."""
    del LMIS[key]


def routes() -> dict[str, list[str]]:
    """The certificates the registered LMIs offer, in the order registered: ``{route: [its LMI keys]}``
    (Theorem 3's (45), (46) first: the default; Theorem 1's (29) where they do not hold)."""
    out: dict[str, list[str]] = {}
    for k, lmi in LMIS.items():
        if lmi.route:
            out.setdefault(lmi.route, []).append(k)
    return out


def block_sizes(aug: Augmented) -> dict:
    """The sizes of the diagonal blocks of every registered LMI, by key."""
    return {k: list(e.blocks(aug)) for k, e in LMIS.items()}


def _parameters(params: dict):
    return params["sigma"], params["gamma"], params["gamma1"], params.get("gamma2", params["gamma"])


def _at_45(aug, d: dict, params: dict):
    s, g, g1, _ = _parameters(params)
    X, K = d["X"], d["K"]
    for i in range(aug.r):
        for j in distinct(K):
            yield lmi45(aug, i, X, K[j] @ X, s, g, g1)


def _at_decay(aug, d: dict, params: dict):
    beta = float(params.get("beta", 0.0))
    X, K = d["X"], d["K"]
    for i in range(aug.r):
        for j in distinct(K):
            yield lmi_decay(aug, i, X, K[j] @ X, beta)


def _at_46(aug, d: dict, params: dict):
    s, _, g1, g2 = _parameters(params)
    K = d["K"]
    for i in range(aug.r):
        for j in distinct(K):
            yield lmi46(aug, i, K[j], d["P"], d["T"], d["Pbar"], d["Q"][i], s, g1, g2)


def _at_29(aug, d: dict, params: dict):
    """(29) at the design's ``P29``; nothing for a design without one (made by (45)-(46), which imply (29) at
    ``P = X^-1``, Theorem 2): its certificate then has no key "29", as documents older than it."""
    P1 = d.get("P29")
    if P1 is None:
        return
    _, g, _, g2 = _parameters(params)
    K = d["K"]
    for i in range(aug.r):
        for j in distinct(K):
            yield lmi29(aug, i, K[j], P1, d["T"], d["Pbar"], d["Q"][i], g, g2)


def _at_55(aug, d: dict, params: dict):
    yield lmi55(aug, d["T"], d["Pbar"], d["N"], d["theta"])


def _at_64(aug, d: dict, params: dict):
    for i in range(aug.r):
        yield lmi64(aug, i, d["T"], d["Pbar"], d["theta"])


def _theta_max_eig(L: np.ndarray, blocks) -> float:
    return theta_lmi_max_eig(L, blocks[0])


def _blocks_46(aug):
    return [aug.n, aug.ld, aug.nbar] + ([aug.Mbar[0].shape[1]] if aug.Mbar[0].shape[1] else [])


#: the two certificates (routes) a design can have: the paper's (45)-(46), and Theorem 1's (29) where they do not hold
THEOREM3, THEOREM1 = "Theorem 3", "Theorem 1"
register(LMI("45", "78", "the state-feedback loop: X, K_j, the attenuation gamma of d (step 3)", _at_45,
             lambda aug: [aug.n, aug.n, aug.p, aug.ld], route=THEOREM3,
             pose={STEP3: Posing(_pose45, soft=True), PAPER3: Posing(_paper45)}))  # fmt: skip
register(LMI("decay", None, "the closed loop's decay rate beta (params.beta, 0 when absent): A_i X + X A_i^T + "
             "B_i Y_j + Y_j^T B_i^T + 2 beta X < 0 (step 3; not in the paper)", _at_decay, lambda aug: [aug.n],
             pose={STEP3: Posing(_pose_decay, soft=True)}))  # fmt: skip
register(LMI("46", "79", "the observer: Pbar, Q_i at the loop's K_j, the attenuation gamma1 (step 5)", _at_46,
             _blocks_46, route=THEOREM3, pose={STEP5: Posing(_pose46), PAPER5: Posing(_paper46)}))  # fmt: skip
register(LMI("29", None, "the closed loop (27) with V = x^T P29 x + e^T Pbar e at the loop's K: mean-square "
             "stability and the attenuation gamma (Theorem 1; where (45)-(46) do not hold)", _at_29, _blocks_46,
             route=THEOREM1, pose={JOINT: Posing(_pose29)}))  # fmt: skip
register(LMI("55", "80", "the sliding surface (20): ||J1^T T^T Pbar - N Cbar||^2 <= theta", _at_55,
             lambda aug: [aug.nbar, aug.ns], _theta_max_eig,
             pose={STEP5: Posing(_pose55, "rest"), JOINT: Posing(_pose55, "rest"), PAPER5: Posing(_paper55)}))  # fmt: skip
register(LMI("64", "81", "the diffusion the sliding variable sees: ||J1^T T^T Pbar T Wbar_i||^2 <= theta", _at_64,
             lambda aug: [aug.n, aug.ns], _theta_max_eig,
             pose={STEP5: Posing(_pose64, "rest"), JOINT: Posing(_pose64, "rest"), PAPER5: Posing(_paper64)}))  # fmt: skip
