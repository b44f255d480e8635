"""A loaded design re-certified at its own numbers: the certificate of :mod:`.certify` recomputed with
numpy (no solve; milliseconds for the built-in plants), at the matrices the discrete step uses.

The step runs on ``K``, ``L1``, ``L2``, ``R``, ``T``, ``H``, ``N`` and ``Ls``; the certificate speaks of
``X``, ``P``, ``Pbar``, ``Q`` and ``theta``. So the observer is rebuilt from the loaded ``L1``
(``Q_i = Pbar L1_i``, ``R_i = T Abar_i - L1_i Cbar``), the loaded ``R``, ``L2``, ``T``, ``P`` and ``Ls`` must
agree with what they are made of, and then every LMI and every eigenvalue condition is evaluated.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._augment import augment
from .core._certify import certificate, discrete_certificate, failures
from .core._lmis import LMIS, distinct

__all__ = []  # public: docs/api.md

#: how far (relative) a stored matrix may be from what it is made of: the design writes them with
#: 17 significant digits, so anything above round-off is an edit
_REL = 1e-6


def _far(stored: np.ndarray, made: np.ndarray) -> float:
    scale = max(float(np.max(np.abs(made))), float(np.max(np.abs(stored))), 1e-300) if made.size else 1.0
    return float(np.max(np.abs(stored - made))) / scale if made.size else 0.0


def recertify(d) -> list[str]:
    """What does not hold at the numbers of the design ``d`` (empty: certified), each item a phrase such as
    ``"LMI (45) recomputes to +34.6 at the loaded numbers (it must be negative)"``."""
    aug = augment(d.local_models, d.C, d.Df)
    if d.remark5.get("used"):
        aug = dataclasses.replace(aug, Jd=np.asarray(d.remark5["Bdu"], dtype=float))
    out: list[str] = []
    T, H, Pbar = np.asarray(d.T), np.asarray(d.H), np.asarray(d.Pbar)
    L1 = [np.asarray(M) for M in d.L1]
    R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
    Q = [Pbar @ M for M in L1]
    for name, stored, made, how in (
        ("T", [T], [np.eye(aug.nbar) - H @ aug.Cbar], "I - H Cbar"),
        ("P", [np.asarray(d.P)], [np.linalg.pinv(np.asarray(d.X))], "X^-1"),
        ("Ls", [np.asarray(d.Ls)], [T @ aug.Js], "T J1"),
        ("R", [np.asarray(M) for M in d.R], R, "T Abar_i - L1_i Cbar"),
        ("L2", [np.asarray(M) for M in d.L2], [Ri @ H for Ri in R], "R_i H"),
    ):
        for i, (a, b) in enumerate(zip(stored, made)):
            gap = _far(a, b)
            if not gap <= _REL:
                which = name if len(stored) == 1 else f"{name}_{i + 1}"
                out.append(f"{which} is not {how.replace('_i', f'_{i + 1}')} (off by {gap:.3g} relative)")
    point = dict(X=np.asarray(d.X), K=[np.asarray(M) for M in d.K], P=np.asarray(d.P), T=T, Pbar=Pbar, Q=Q,
                 N=np.asarray(d.N), theta=float(d.theta), R=R, L1=L1)  # fmt: skip
    try:
        checks = certificate(aug, point, d.params.to_dict())
    except np.linalg.LinAlgError as exc:
        return out + [f"the certificate cannot be evaluated at the loaded numbers ({exc})"]
    sample_time = d.observer.sample_time
    if sample_time is not None:
        checks["discrete"] = discrete_certificate(R, Pbar, float(sample_time))
    for k, lmi in LMIS.items():
        v = checks["lmi_max_eig"][k]
        if not v < 0:
            out.append(
                f"{lmi.name(checks.get('theorem'))} recomputes to {v:+.3g} at the loaded numbers (it must be negative)"
            )
    for i, Ri in enumerate(R):
        top = float(np.max(np.linalg.eigvals(Ri).real))
        if not top < 0:
            out.append(f"the observer matrix R_{i + 1} = T Abar_{i + 1} - L1_{i + 1} Cbar has an eigenvalue with real "
                       f"part {top:+.3g}")  # fmt: skip
    for i in range(aug.r):
        for j in distinct(point["K"]):
            Kj = point["K"][j]
            top = float(
                np.max(np.linalg.eigvals(aug.Abar[i][: aug.n, : aug.n] + aug.Bbar[i][: aug.n] @ Kj).real)
            )
            if not top < 0:
                out.append(
                    f"the closed loop A_{i + 1} + B_{i + 1} K_{j + 1} has an eigenvalue with real part {top:+.3g}"
                )
    said = ("LMI (", "R_i Hurwitz", "A_i + B_i K_j Hurwitz")
    out += [f for f in failures(checks) if not f.startswith(said) or "within the round-off" in f]
    return out
