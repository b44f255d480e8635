"""The augmented system (8) of the paper, for any number of rules, states and faults.

With ``xbar = [x; fdot; f]`` (``nbar = n + 2 lf``)::

    Abar_i = [[A_i, 0, Bf_i], [0, 0, 0], [0, I, 0]]     Bbar_i = [B_i; 0; 0]
    Bdbar_i = [Bd_i; 0; 0]    Wbar_i = [W_i; 0; 0] (nbar x n)    Cbar = [C, 0, Df]
    J0 = [I, 0, 0] (n x nbar)   J1 = [0; I; 0] (nbar x lf)   J2 = [0, 0, I] (lf x nbar)

Theorem 5 (Section 5) adds ``Gbar_i = [G_i; 0; 0]``, ``Gfbar_i = [Gf_i; 0; 0]`` and
``Mbar_i = [M_i; 0; 0]``.

Remark 5 (when H cannot decouple every unknown input) replaces ``J1`` by ``[Bdbar_u J1]`` in the
sliding term: :attr:`Augmented.Jd` holds the undecoupled directions ``Bdbar_u`` (nbar x k, empty
without Remark 5) and :attr:`Augmented.Js` the widened ``[Bdbar_u J1]`` that (20), (55), (64) use.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from ..ts import LocalModel

__all__ = ["Augmented", "augment", "time_scaled"]  # public: docs/api.md


def pad_rows(M: np.ndarray, lf: int) -> np.ndarray:
    """``[M; 0; 0]``: append ``2 lf`` zero rows (the fdot and f blocks of xbar)."""
    M = np.atleast_2d(np.asarray(M, dtype=float))
    return np.vstack([M, np.zeros((2 * lf, M.shape[1]))])


@dataclass(frozen=True)
class Augmented:
    """The augmented matrices of (8) (and (76)), one entry per rule in the tuples."""

    n: int
    m: int
    p: int
    ld: int
    lf: int
    r: int
    Abar: tuple[np.ndarray, ...]
    Bbar: tuple[np.ndarray, ...]
    Bdbar: tuple[np.ndarray, ...]
    Wbar: tuple[np.ndarray, ...]
    Gbar: tuple[np.ndarray, ...]
    Gfbar: tuple[np.ndarray, ...]
    Mbar: tuple[np.ndarray, ...]
    Cbar: np.ndarray
    J0: np.ndarray
    J1: np.ndarray
    J2: np.ndarray
    #: Remark 5: the directions of d that H does not decouple (nbar x k; k = 0 without Remark 5)
    Jd: np.ndarray | None = None

    @property
    def nbar(self) -> int:
        return self.n + 2 * self.lf

    @property
    def Js(self) -> np.ndarray:
        """The sliding directions: ``J1``, or ``[Bdbar_u J1]`` with Remark 5 (nbar x ns)."""
        return self.J1 if self.Jd is None or self.Jd.shape[1] == 0 else np.hstack([self.Jd, self.J1])

    @property
    def ns(self) -> int:
        """Number of sliding variables: ``lf``, plus the undecoupled directions with Remark 5."""
        return self.Js.shape[1]


def augment(local_models: Sequence, C: np.ndarray, Df: np.ndarray) -> Augmented:
    """Build (8) from local models (:class:`~fte_casadi.ts._model.LocalModel` records, or dicts with A, B,
    Bd, Bf, W[, a, G, Gf, M], which become records).

    Examples
    --------
    >>> import numpy as np
    >>> lm = dict(A=-np.eye(2), B=np.eye(2)[:, :1], Bd=np.ones((2, 1)), Bf=np.eye(2)[:, :1], W=0 * np.eye(2))
    >>> aug = augment([lm], np.eye(2), np.zeros((2, 1)))
    >>> aug.nbar, aug.Abar[0].shape, aug.Cbar.shape
    (4, (4, 4), (2, 4))
    """
    C = np.atleast_2d(np.asarray(C, dtype=float))
    p, n = C.shape
    Df = np.asarray(Df, dtype=float).reshape(p, -1)
    lf = Df.shape[1]
    nbar = n + 2 * lf
    Abar, Bbar, Bdbar, Wbar, Gbar, Gfbar, Mbar = ([] for _ in range(7))
    m = ld = 0
    for lm in map(LocalModel.from_mapping, local_models):
        A = lm.A
        B = lm.B.reshape(n, -1)
        Bd = lm.Bd.reshape(n, -1)
        Bf = lm.Bf.reshape(n, lf)
        W = lm.W.reshape(n, n)
        m, ld = B.shape[1], Bd.shape[1]
        Ab = np.zeros((nbar, nbar))
        Ab[:n, :n] = A
        Ab[:n, n + lf :] = Bf
        Ab[n + lf :, n : n + lf] = np.eye(lf)
        Abar.append(Ab)
        Bbar.append(pad_rows(B, lf))
        Bdbar.append(pad_rows(Bd, lf))
        Wbar.append(pad_rows(W, lf))
        G = _columns(lm.G, n)
        Gf = _columns(lm.Gf, n)
        M = _columns(lm.M, n)
        Gbar.append(pad_rows(G, lf))
        Gfbar.append(pad_rows(Gf, lf))
        Mbar.append(pad_rows(M, lf) if M.size else np.zeros((nbar, 0)))
    J0 = np.hstack([np.eye(n), np.zeros((n, 2 * lf))])
    J1 = np.vstack([np.zeros((n, lf)), np.eye(lf), np.zeros((lf, lf))])
    J2 = np.hstack([np.zeros((lf, n + lf)), np.eye(lf)])
    Cbar = np.hstack([C, np.zeros((p, lf)), Df])
    return Augmented(
        n, m, p, ld, lf, len(Abar), tuple(Abar), tuple(Bbar), tuple(Bdbar), tuple(Wbar),
        tuple(Gbar), tuple(Gfbar), tuple(Mbar), Cbar, J0, J1, J2,
    )  # fmt: skip


def _columns(v: np.ndarray, n: int) -> np.ndarray:
    """``v`` as n rows (an empty matrix as n rows of no column)."""
    return np.zeros((n, 0)) if v.size == 0 else v.reshape(n, -1)


def time_scale(aug: Augmented) -> float:
    """The plant's characteristic time ``tau``: the power of two nearest ``1 / max_i ||A_i||_2``.

    A power of two, so that multiplying data by it is exact; 1 when every A_i is zero.
    """
    rho = max(float(np.linalg.norm(A[: aug.n, : aug.n], 2)) for A in aug.Abar)
    if not (rho > 0 and np.isfinite(rho)):
        return 1.0
    return float(2.0 ** round(-np.log2(rho)))


def time_scaled(aug: Augmented, tau: float) -> Augmented:
    """(8) in the time ``t' = t / tau``: drift and input matrices times ``tau``, diffusion times ``sqrt(tau)``.

    With ``sigma' = tau^2 sigma`` and ``alpha' = tau alpha``, LMI (45) of the scaled data at
    ``X' = tau X`` (the same gain K) is a congruence of (45) at ``X``, and (46) at
    ``(P', Pbar', Q') = (P / tau, Pbar / tau, Q)`` a congruence of (46) at ``(P, Pbar, Q)``: the
    same problem in numbers of order one for a plant whose rates are far from 1/s.
    """
    if tau == 1.0:
        return aug
    rt = float(np.sqrt(tau))
    return replace(
        aug,
        Abar=tuple(tau * A for A in aug.Abar),
        Bbar=tuple(tau * B for B in aug.Bbar),
        Bdbar=tuple(tau * B for B in aug.Bdbar),
        Wbar=tuple(rt * W for W in aug.Wbar),
        Gbar=tuple(rt * G for G in aug.Gbar),
        Gfbar=tuple(rt * G for G in aug.Gfbar),
        Mbar=tuple(rt * M for M in aug.Mbar),
    )


def output_scale(aug: Augmented) -> float:
    """The outputs' characteristic size ``sy``: the power of two nearest the largest row norm of C (1 when C is zero).

    Outputs measured in mm of a state in m give ``sy = 1024``; LMI (45) holds ``C X`` beside ``-I``, so a
    feasible X is ``sy^2`` times smaller than for the same plant measured in m, and sigma with it.
    """
    return output_size(aug.Cbar[:, : aug.n])


def output_size(C) -> float:
    """The power of two nearest the largest row norm of ``C`` (1 when C is zero): :func:`output_scale` of a
    plant's output matrix, for code that has C before the augmented model."""
    C = np.asarray(C, dtype=float)
    c = float(np.max(np.linalg.norm(C, axis=1), initial=0.0)) if C.size else 0.0
    if not (c > 0 and np.isfinite(c)):
        return 1.0
    return float(2.0 ** round(np.log2(c)))


def unknown_input_size(aug: Augmented) -> float:
    """The unknown inputs' own size ``sd``: how far the largest of them moves the outputs while its direction
    lasts, in units of the outputs' size: ``max_{i,j} ||C A_i^k b||_2 t_ij^(k+1) / sy`` with ``b = Bd_i e_j``,
    ``t_ij = ||b|| / ||A_i b||`` the time the plant takes to turn d's direction (``tau``,
    :func:`time_scale`, where ``A_i b = 0``) and k the first power for which the outputs see b (k = 0,
    ``C Bd_i``, under assumption (1)); 1 without unknown inputs or when the outputs see none.

    Covariant: an unknown input measured in another unit, ``d' = c d`` (``Bd' = Bd / c``), has
    ``sd' = sd / c`` (t_ij does not change); outputs ``k`` times larger (k a power of two) leave it as it is.
    Not rounded (a power of two would keep the covariance only for c a power of two): a design at
    ``gamma = g sy sd`` is the same design whatever unit d is in (:func:`~fte_casadi.design._options._generic_scale`).
    ``t_ij`` rather than the plant's fastest time ``tau``: a flexible joint whose load torque d acts on the
    slow link (16 rad/s) while the motor's spring sets ``tau = 2^-11 s`` needs gamma 170 times the value
    ``tau`` gives, and 12 times less than ``t_ij`` gives (docs/design.md).
    """
    n = aug.n
    if aug.ld == 0:
        return 1.0
    tau, sy = time_scale(aug), output_scale(aug)
    C = aug.Cbar[:, :n]
    best = 0.0
    for j in range(aug.ld):
        for k in range(n):
            sizes = []
            for A, Bd in zip(aug.Abar, aug.Bdbar):
                A, b = A[:n, :n], Bd[:n, j]
                nb, nab = np.linalg.norm(b), np.linalg.norm(A @ b)
                t = nb / nab if nab > 1e-12 * np.linalg.norm(A, 2) * nb else tau
                v = b
                for _ in range(k):
                    v = A @ v
                tol = 1e-12 * np.linalg.norm(C, 2) * max(np.linalg.norm(A, 2), 1.0 / tau) ** k * nb
                w = float(np.linalg.norm(C @ v))
                sizes.append(w * t ** (k + 1) if w > tol else 0.0)
            if max(sizes) > 0:
                best = max(best, max(sizes) / sy)
                break
    return best if best > 0 and np.isfinite(best) else 1.0


def units_scaled(aug: Augmented, tau: float, sy: float, sd: float = 1.0) -> Augmented:
    """(8) in the time ``t / tau`` (:func:`time_scaled`) with outputs divided by ``sy``: ``Cbar / sy``, and the
    unknown inputs in units ``sd`` times larger: ``Bdbar / sd`` (:func:`unknown_input_size`).

    LMI (45) of these data at ``(sigma tau^2 sy^2, gamma / (sy sd), gamma1 / (sy sd))`` and ``X~ = tau sy^2 X``
    (the same gain K) is a congruence of (45) at ``(sigma, gamma, gamma1)`` and X, times ``sy^2``: multiply
    (45) by ``sy^2``, then take the congruence ``diag(I, I, I / sy, I / (sy^2 sd))`` of its (x, x, y, d)
    blocks (the time's part as in :func:`time_scaled`). tau and sy are powers of two, so their part of the
    map is exact; sd is not (an unknown input's unit is any number), and d's block only meets X through
    ``Bd``: the unknowns ``(X, Y)`` of the map are the same whatever sd is.
    """
    out = time_scaled(aug, tau)
    if sy != 1.0:
        out = replace(out, Cbar=aug.Cbar / sy)
    if sd != 1.0:
        out = replace(out, Bdbar=tuple(B / sd for B in out.Bdbar))
    return out


def units_params(params: dict, tau: float, sy: float, sd: float = 1.0) -> dict:
    """The parameters of (45) in the units of :func:`units_scaled` (sigma, gamma, gamma1; gamma2, the d2
    attenuation, in the outputs' size only; the rest as given)."""
    out = dict(params, sigma=params["sigma"] * tau**2 * sy**2)
    for k in ("gamma", "gamma1", "gamma2"):
        if out.get(k) is not None:
            out[k] = out[k] / (sy if k == "gamma2" else sy * sd)
    return out
