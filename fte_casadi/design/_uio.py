"""Unknown-input decoupling gain H by (17)-(18), and the assumption checks of Section 3.

H
    ``[Bdbar_1 ... Bdbar_r]`` is column-compressed to a full-column-rank ``B_U`` by an SVD
    (rank = number of singular values above ``RANK_RTOL * s_max``; ``B_U = U_k S_k``, which is
    ``(18)`` with ``U = V``), then ``H = B_U ((Cbar B_U)^T (Cbar B_U))^-1 (Cbar B_U)^T`` (17) and
    ``T = I - H Cbar`` (14). H does not depend on the basis chosen for ``range(B_U)``, so it
    equals the paper's printed H. With no unknown input (``ld = 0``) ``H = 0``.

Assumption checks (each returns an :class:`AssumptionCheck`; :func:`enforce` raises
:class:`~fte_casadi.errors.AssumptionError` for failures the caller does not accept):

(1) ``rank(Cbar Bdbar) = rank(Bdbar)`` — d can be decoupled (Remark 5 otherwise);
(2) ``[[A_i, Bf_i, Bd_i], [C, Df, 0]]`` of full column rank, every rule;
(3) invariant zeros of ``(A_i, Bd_i, C)`` in the open left half plane (finite generalised
    eigenvalues of the Rosenbrock pencil, squared down by a projection of the outputs when
    ``p > ld`` and every candidate verified on the full pencil);
(4) the pair ``(T Abar_i, Cbar)`` observable (PBH test at each eigenvalue); an unobservable
    but stable eigenvalue (detectable pair) is a warning, an unstable one a failure;
(5) ``rank [B_i Bf_i] = rank B_i`` (checked at every rule), so ``Kf = -pinv(B_h) Bf_h``
    cancels the actuator faults.

Remark 5 (:func:`remark5_split`): when H cannot decouple every direction of d, H decouples the
directions ``D`` it can, and the rest, ``T Bdbar_i = Bdbar_u M_i`` (``Bdbar_u`` orthonormal, common
to the rules), joins the sliding term: ``J1`` becomes ``[Bdbar_u J1]`` and ``f''`` becomes
``[M(h) d; f'']``. The paper's ``Bdbar_u_i`` is ``Bdbar_i`` in a rule where (1) fails; through
``T`` only ``T Bdbar_i`` of it acts on the error, and a common basis of those gives one sliding
variable for every rule (the paper's per-rule ``L_si = T [Bdbar_u_i J1]`` factor through it).
Assumption (3) is then asked of the decoupled directions ``D`` only; (2) of every unknown input.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import numpy as np
import scipy.linalg as sla

from ..errors import AssumptionError
from ._augment import Augmented

__all__ = [
    "AssumptionCheck",
    "uio_gain",
    "check_assumptions",
    "enforce",
    "invariant_zeros",
]  # public: docs/api.md

#: relative tolerance of every numerical rank decision (singular values below it times the largest are zero)
RANK_RTOL = 1e-9


@dataclass(frozen=True)
class AssumptionCheck:
    """The outcome of one assumption check."""

    name: str
    holds: bool
    message: str
    numbers: dict = field(default_factory=dict)
    warning: bool = False  # holds only in a weaker sense (e.g. detectable, not observable)
    #: whether designing with this failure accepted can succeed (False: no hint to accept it is offered)
    acceptable: bool = True

    def to_dict(self) -> dict:
        return {"name": self.name, "holds": self.holds, "warning": self.warning, "message": self.message,
                "numbers": self.numbers}  # fmt: skip


def rank(M: np.ndarray, rtol: float = RANK_RTOL) -> int:
    M = np.atleast_2d(M)
    if M.size == 0:
        return 0
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > rtol * max(s[0], 1e-300))) if s[0] > 0 else 0


def column_compress(Bd_all: np.ndarray, rtol: float = RANK_RTOL) -> np.ndarray:
    """(18): a full-column-rank ``B_U`` spanning the columns of ``Bd_all`` (SVD, tolerance ``rtol``)."""
    if Bd_all.size == 0:
        return np.zeros((Bd_all.shape[0], 0))
    U, s, _ = np.linalg.svd(Bd_all, full_matrices=False)
    k = int(np.sum(s > rtol * s[0])) if s[0] > 0 else 0
    return U[:, :k] * s[:k]


def uio_gain(aug: Augmented, rtol: float = RANK_RTOL) -> tuple[np.ndarray, np.ndarray]:
    """``(H, T)`` of (17), (14). When ``Cbar B_U`` lacks full column rank (assumption (1)
    fails) the pseudo-inverse decouples the part of d that can be decoupled."""
    nbar, p = aug.nbar, aug.p
    BU = column_compress(np.hstack(aug.Bdbar), rtol)
    if BU.shape[1] == 0:
        H = np.zeros((nbar, p))
    else:
        CBU = aug.Cbar @ BU
        if rank(CBU, rtol) == BU.shape[1]:
            H = BU @ np.linalg.solve(CBU.T @ CBU, CBU.T)
        else:
            H = BU @ np.linalg.pinv(CBU, rcond=rtol)
    return H, np.eye(nbar) - H @ aug.Cbar


def decoupling_gain(aug: Augmented, D: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``(H, T)`` decoupling the directions ``D`` (nbar x q, ``Cbar D`` of full column rank):
    ``H = D ((Cbar D)^T (Cbar D))^-1 (Cbar D)^T``, (17) with ``B_U = D``; ``T = I - H Cbar``."""
    if D.shape[1] == 0:
        H = np.zeros((aug.nbar, aug.p))
    else:
        CD = aug.Cbar @ D
        H = D @ np.linalg.solve(CD.T @ CD, CD.T)
    return H, np.eye(aug.nbar) - H @ aug.Cbar


@dataclass(frozen=True)
class Remark5:
    """Remark 5's split of the unknown inputs: what H decouples, and what the sliding term attenuates.

    ``D`` (nbar x q): the directions H decouples. ``Bdu`` (nbar x k, orthonormal columns): the
    directions left, with ``T Bdbar_i = Bdu M_i`` for every rule (``M`` holds the k x ld ``M_i``).
    ``inputs``: indices of the unknown inputs with an undecoupled part. ``why``: which assumption
    made it necessary, in words."""

    D: np.ndarray
    Bdu: np.ndarray
    M: tuple
    inputs: tuple
    H: np.ndarray
    T: np.ndarray
    why: str

    def gains(self, d_bound: np.ndarray, epsilon: float) -> np.ndarray:
        """The sliding gain of each undecoupled direction: a bound on ``|(M(h) d)_k|`` plus ``epsilon``,
        ``sum_j max_i |M_i[k, j]| d_bound_j + epsilon`` (``|d_j| <= d_bound_j``; any memberships)."""
        A = np.max(np.abs(np.stack(self.M)), axis=0)  # k x ld
        return A @ np.asarray(d_bound, dtype=float) + float(epsilon)


def remark5_split(aug: Augmented, D: np.ndarray | None = None, why: str = "",
                  rtol: float = RANK_RTOL) -> Remark5 | None:  # fmt: skip
    """Remark 5's split (module docstring). ``D`` default: the directions of ``[Bdbar_1 ... Bdbar_r]``
    that the outputs see (``B_U V1``, ``V1`` the right singular vectors of ``Cbar B_U`` with a
    nonzero singular value), which gives the same H as :func:`uio_gain`. None when nothing is left
    undecoupled."""
    BU = column_compress(np.hstack(aug.Bdbar), rtol)
    if BU.shape[1] == 0:
        return None
    if D is None:
        _, sv, Vt = np.linalg.svd(aug.Cbar @ BU)
        q = int(np.sum(sv > rtol * max(sv[0], 1e-300))) if sv.size and sv[0] > 0 else 0
        D = BU @ Vt[:q].T
    H, T = decoupling_gain(aug, D)
    left = np.hstack([T @ B for B in aug.Bdbar])
    U, sv, _ = np.linalg.svd(left, full_matrices=False)
    scale = max(np.linalg.norm(np.hstack(aug.Bdbar), 2), 1e-300)
    k = int(np.sum(sv > rtol * scale))
    if k == 0:
        return None
    Bdu = U[:, :k]
    M = tuple(Bdu.T @ T @ B for B in aug.Bdbar)  # exact: T Bdbar_i lies in range(Bdu), Bdu orthonormal
    tol = rtol * scale
    inputs = tuple(j for j in range(aug.ld) if any(np.linalg.norm(Mi[:, j]) > tol for Mi in M))
    return Remark5(D, Bdu, M, inputs, H, T, why)


def check_decoupling(aug: Augmented) -> AssumptionCheck:
    Bd = np.hstack(aug.Bdbar)
    r1, r2 = rank(aug.Cbar @ Bd), rank(Bd)
    ok = r1 == r2
    msg = (f"assumption (1) holds: {_decoupling_ranks(r1, r2)}" if ok else
           f"assumption (1) fails: {_decoupling_ranks(r1, r2)}; the unknown input cannot be "
           "decoupled by H. Remark 5's fallback (applied by default; --no-remark5 / remark5=False turned it off): replace J1 by [Bdbar_u J1] so that the sliding term attenuates the "
           "part of d that H cannot decouple, or measure more outputs")  # fmt: skip
    return AssumptionCheck("(1)", ok, msg, {"rank_CBd": r1, "rank_Bd": r2})


def _decoupling_ranks(r1: int, r2: int) -> str:
    """Assumption (1)'s ranks, ``rank(Cbar Bdbar) = r1`` and ``rank(Bdbar) = r2``, as its message says them."""
    return (
        f"rank(Cbar Bdbar) = rank(Bdbar) = {r2}"
        if r1 == r2
        else f"rank(Cbar Bdbar) = {r1} < rank(Bdbar) = {r2}"
    )


def check_full_column_rank(aug: Augmented, models) -> AssumptionCheck:
    bad = []
    ranks = []
    Df = aug.Cbar[:, aug.n + aug.lf :]
    C = aug.Cbar[:, : aug.n]
    for i, (Ab, Bdb) in enumerate(zip(aug.Abar, aug.Bdbar)):
        A, Bf, Bd = Ab[: aug.n, : aug.n], Ab[: aug.n, aug.n + aug.lf :], Bdb[: aug.n]
        M = np.block([[A, Bf, Bd], [C, Df, np.zeros((aug.p, aug.ld))]])
        k = rank(M)
        ranks.append(k)
        if k < M.shape[1]:
            bad.append(i + 1)
    cols = aug.n + aug.lf + aug.ld
    ok = not bad
    msg = (f"assumption (2) holds: [[A_i, Bf_i, Bd_i], [C, Df, 0]] has full column rank {cols} for every rule" if ok
           else f"assumption (2) fails for rule(s) {bad}: [[A_i, Bf_i, Bd_i], [C, Df, 0]] has rank {min(ranks)} "
           f"< {cols} columns; faults and unknown inputs cannot be told apart from the outputs"
           + (f" (it needs at least as many outputs as faults plus unknown inputs: {aug.p} < {aug.lf + aug.ld}; "
              "measure more, or model fewer faults or unknown inputs)" if aug.p < aug.lf + aug.ld else ""))  # fmt: skip
    return AssumptionCheck("(2)", ok, msg, {"ranks": ranks, "columns": cols})


def invariant_zeros(A: np.ndarray, Bd: np.ndarray, C: np.ndarray, seed: int = 0) -> np.ndarray | None:
    """Finite invariant zeros of ``(A, Bd, C)``: the s where ``[[sI - A, Bd], [C, 0]]`` loses rank.

    Returns ``None`` when the pencil has normal rank below ``n + ld`` (rank lost for every s,
    e.g. fewer outputs than unknown inputs).
    """
    n, ld, p = A.shape[0], Bd.shape[1], C.shape[0]
    rng = np.random.default_rng(seed)
    s_test = complex(rng.normal(), rng.normal())
    full = np.block([[s_test * np.eye(n) - A, Bd], [C, np.zeros((p, ld))]])
    if rank(full) < n + ld:
        return None
    R = np.eye(p) if p == ld else np.linalg.qr(rng.normal(size=(p, ld)))[0].T  # ld x p projection
    Mp = np.block([[A, -Bd], [-(R @ C), np.zeros((ld, ld))]])
    Ep = np.block([[np.eye(n), np.zeros((n, ld))], [np.zeros((ld, n + ld))]])
    w = sla.eig(Mp, Ep, right=False)
    cand = w[np.isfinite(w)]
    scale = max(1.0, np.linalg.norm(A, 2), np.linalg.norm(Bd, 2), np.linalg.norm(C, 2))
    zeros = []
    for s in cand:
        Ms = np.block([[s * np.eye(n) - A, Bd], [C, np.zeros((p, ld))]])
        if np.linalg.svd(Ms, compute_uv=False)[-1] <= 1e-7 * scale * max(1.0, abs(s)):
            zeros.append(s)
    return np.array(zeros, dtype=complex)


def check_invariant_zeros(aug: Augmented) -> AssumptionCheck:
    n, C = aug.n, aug.Cbar[:, : aug.n]
    worst = []
    msgs = []
    ok = True
    for i, (Ab, Bdb) in enumerate(zip(aug.Abar, aug.Bdbar)):
        if aug.ld == 0:
            break
        z = invariant_zeros(Ab[:n, :n], Bdb[:n], C)
        if z is None:
            ok = False
            msgs.append(f"rule {i + 1}: [[sI - A, Bd], [C, 0]] has rank < n + ld = {n + aug.ld} for every s")
            continue
        worst.append([[float(v.real), float(v.imag)] for v in z])
        for v in z:
            if v.real >= 0:
                ok = False
                msgs.append(f"rule {i + 1}: invariant zero at s = {_fmt(v)} in the right half plane")
    msg = (
        (
            "assumption (3) holds: every invariant zero of (A_i, Bd_i, C) lies in the open left half plane"
            + ("" if any(worst) else " (there are none)")
        )
        if ok
        else "assumption (3) fails: " + "; ".join(msgs)
    )
    return AssumptionCheck("(3)", ok, msg, {"zeros": worst})


def check_observability(aug: Augmented, T: np.ndarray) -> AssumptionCheck:
    Cb = aug.Cbar
    unobs = []
    for i, Ab in enumerate(aug.Abar):
        M = T @ Ab
        scale = max(1.0, np.linalg.norm(M, 2), np.linalg.norm(Cb, 2))
        for lam in np.linalg.eigvals(M):
            pbh = np.vstack([lam * np.eye(aug.nbar) - M, Cb])
            if np.linalg.svd(pbh, compute_uv=False)[-1] <= 1e-8 * scale:
                unobs.append((i + 1, lam))
    unstable = [(i, v) for i, v in unobs if v.real >= 0]
    nums = {"unobservable": [[i, float(v.real), float(v.imag)] for i, v in unobs]}
    if not unobs:
        return AssumptionCheck(
            "(4)", True, "assumption (4) holds: (T Abar_i, Cbar) is observable for every rule", nums
        )
    lst = _grouped(unstable or unobs)
    if unstable:
        return AssumptionCheck("(4)", False, f"assumption (4) fails: (T Abar_i, Cbar) has the unobservable, "
                               f"non-decaying eigenvalue(s) {lst}; no observer gain can make R_i Hurwitz", nums)  # fmt: skip
    return AssumptionCheck("(4)", True, f"assumption (4) holds only as detectability: (T Abar_i, Cbar) has the "
                           f"unobservable but stable eigenvalue(s) {lst}", nums, warning=True)  # fmt: skip


def check_fault_matching(aug: Augmented) -> AssumptionCheck:
    bad = []
    for i, (Ab, Bb) in enumerate(zip(aug.Abar, aug.Bbar)):
        B, Bf = Bb[: aug.n], Ab[: aug.n, aug.n + aug.lf :]
        if rank(np.hstack([B, Bf])) != rank(B):
            bad.append(i + 1)
    if not bad:
        return AssumptionCheck("(5)", True, "assumption (5) holds: rank [B_i Bf_i] = rank B_i for every rule")
    return AssumptionCheck("(5)", False, f"assumption (5) fails for rule(s) {bad}: rank [B_i Bf_i] > rank B_i, so "
                           "Kf = -pinv(B_h) Bf_h cannot cancel the actuator faults", {"rules": bad})  # fmt: skip


def check_assumptions(
    aug: Augmented, T: np.ndarray, models=None, remark5: Remark5 | None = None
) -> list[AssumptionCheck]:
    """All five checks, in order. With Remark 5, (1) holds by the fallback (its message says what the
    sliding term attenuates) and (3) is asked of the decoupled directions only; (2) keeps every unknown
    input: an attenuated input the outputs cannot tell from a fault still biases its estimate."""
    if remark5 is None:
        return [
            check_decoupling(aug),
            check_full_column_rank(aug, models),
            check_invariant_zeros(aug),
            check_observability(aug, T),
            check_fault_matching(aug),
        ]
    import dataclasses

    first = check_decoupling(aug)
    k, q = remark5.Bdu.shape[1], remark5.D.shape[1]
    ranks = _decoupling_ranks(first.numbers["rank_CBd"], first.numbers["rank_Bd"])
    first = dataclasses.replace(first, holds=True, message=(
        f"assumption (1) {'fails' if not first.holds else 'holds'}: {ranks}; "
        f"{remark5.why + '; ' if remark5.why else ''}Remark 5's fallback is used: H decouples {q} direction(s) of d "
        f"and the sliding term attenuates the {k} it cannot ([Bdbar_u J1] in place of J1)"),
        numbers=dict(first.numbers, remark5=True, decoupled=q, attenuated=k))  # fmt: skip
    dec = dataclasses.replace(aug, Bdbar=tuple(remark5.D for _ in range(aug.r)), ld=q)
    two, three = check_full_column_rank(aug, models), check_invariant_zeros(dec)
    three = dataclasses.replace(three, message=three.message + " (Remark 5: of the part H decouples)")
    return [first, two, three, check_observability(aug, T), check_fault_matching(aug)]


def accepted_names(accept: bool | Iterable[str]) -> set[str] | None:
    """The accepted assumptions as ``{"(2)", ...}`` (``"2"`` or ``"(2)"`` given), None for all (``True``)."""
    if accept is True:
        return None
    return set() if accept is False else {a if a.startswith("(") else f"({a})" for a in accept}


def enforce(checks: Iterable[AssumptionCheck], accept: bool | Iterable[str] = ()) -> list[str]:
    """Raise :class:`AssumptionError` naming every failed check not in ``accept``.

    ``accept`` is ``True`` (accept all) or names such as ``"(3)"`` or ``"3"``. Returns the
    status lines of the accepted failures and of the warnings.
    """
    acc = accepted_names(accept)
    refused, notes, names, hopeless = [], [], [], []
    for c in checks:
        if c.holds:
            if c.warning:
                notes.append("warning: " + c.message)
        elif acc is None or c.name in acc:
            notes.append("accepted: " + c.message)
        else:
            refused.append(c.message)
            (names if c.acceptable else hopeless).append(c.name)
    if refused:
        hint = (
            ". To design anyway (the document records it): "
            + " ".join(f"--accept-assumption {n.strip('()')}" for n in names)
            + " with fte design, or accept_assumptions="
            + repr(names)
            + " in Python"
            if names
            else ""
        )
        if hopeless:
            hint += (
                (". Accepting " if not names else "; accepting ")
                + f"{', '.join(hopeless)} cannot succeed (an unobservable mode that does not decay stays "
                "in every R_i, whatever the observer gain): change the plant's model or measurements"
            )
        raise AssumptionError("; ".join(refused) + hint + ".")
    return notes


def _grouped(eigs: list[tuple[int, complex]]) -> str:
    """``s = 0 (12 times; rules 1, 2)``: each printed value once, with its count and rules."""
    groups: dict[str, list[int]] = {}
    for i, v in eigs:
        groups.setdefault(_fmt(v), []).append(i)
    out = []
    for k, r in groups.items():
        rules = sorted(set(r))
        where = f"rule{'s' if len(rules) > 1 else ''} {', '.join(map(str, rules))}"
        out.append(f"s = {k} ({len(r)} times; {where})" if len(r) > 1 else f"s = {k} ({where})")
    return ", ".join(out)


def _fmt(v: complex) -> str:
    if abs(v.imag) < 1e-9 * max(1.0, abs(v)):
        return f"{v.real:.4g}"
    return f"{v.real:.4g}{v.imag:+.4g}j"
