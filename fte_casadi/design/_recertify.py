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
from .core._certify import Failure, certificate, discrete_certificate, failed
from .core._lmis import LMIS, distinct, loop_decay

__all__ = []  # public: docs/api.md

#: how far (relative) a stored matrix may be from what it is made of: the design writes them with
#: 17 significant digits, so anything above round-off is an edit
_REL = 1e-6


def _far(stored: np.ndarray, made: np.ndarray) -> float:
    scale = max(float(np.max(np.abs(made))), float(np.max(np.abs(stored))), 1e-300) if made.size else 1.0
    return float(np.max(np.abs(stored - made))) / scale if made.size else 0.0


def _augmented(d):
    """The augmented system of ``d`` (with Remark 5's undecoupled directions where its fallback is used)."""
    aug = augment(d.local_models, d.C, d.Df)
    if d.remark5.get("used"):
        aug = dataclasses.replace(aug, Jd=np.asarray(d.remark5["Bdu"], dtype=float))
    return aug


def _stored_point(d, aug) -> dict:
    """The certificate's point at the numbers the step uses: the observer rebuilt from the stored ``L1``
    (``Q_i = Pbar L1_i``, ``R_i = T Abar_i - L1_i Cbar``)."""
    T, Pbar = np.asarray(d.T), np.asarray(d.Pbar)
    L1 = [np.asarray(M) for M in d.L1]
    R = [T @ aug.Abar[i] - L1[i] @ aug.Cbar for i in range(aug.r)]
    return dict(X=np.asarray(d.X), K=[np.asarray(M) for M in d.K], P=np.asarray(d.P), T=T, Pbar=Pbar,
                Q=[Pbar @ M for M in L1], N=np.asarray(d.N), theta=float(d.theta), R=R, L1=L1,
                P29=None if getattr(d, "P29", None) is None else np.asarray(d.P29))  # fmt: skip


def certify(d) -> dict:
    """The certificate of the design ``d`` at its own numbers: every registered LMI and eigenvalue condition
    (:func:`~.core._certify.certificate`) and, at its sample time, the discrete step. The one evaluation of
    "certified": a design is certified when it is made (:func:`~._pipeline.finish` calls this on the record it
    is about to return) exactly when it is certified on load, in ``simulate``, ``codegen``, the FMU and
    ``tune`` (:func:`recertify`): the same numbers (a document holds every double exactly), the same code, the
    same decision (:func:`~.core._certify.failures`)."""
    aug = _augmented(d)
    point = _stored_point(d, aug)
    checks = certificate(aug, point, d.params.to_dict())
    checks["loop"] = loop_record(aug, point["X"], point["K"])
    sample_time = d.observer.sample_time
    if sample_time is not None:
        checks["discrete"] = discrete_certificate(point["R"], point["Pbar"], float(sample_time))
    return checks


def loop_record(aug, X, K) -> dict:
    """How fast the closed loops ``A_i + B_i K_j`` decay: ``decay_certified`` (the largest rate (45) with the
    decay term holds for at the design's X, :func:`~.core._lmis.loop_decay`), ``decay_spectral`` (``min -max Re
    eig(A_i + B_i K_j)``), ``open_loop_decay`` (``min -max Re eig(A_i)``, negative: unstable) and ``gain_ratio``
    (``max ||B_i K_j|| / max ||A_i||``: how much the controller acts against the plant)."""
    n = aug.n
    A = [Ab[:n, :n] for Ab in aug.Abar]
    B = [Bb[:n] for Bb in aug.Bbar]
    js = distinct(K)
    spectral = min(
        -float(np.max(np.linalg.eigvals(A[i] + B[i] @ K[j]).real)) for i in range(aug.r) for j in js
    )
    ol = min(-float(np.max(np.linalg.eigvals(a).real)) for a in A)
    na = max(float(np.linalg.norm(a, 2)) for a in A)
    nbk = max(float(np.linalg.norm(B[i] @ K[j], 2)) for i in range(aug.r) for j in js)
    return {"decay_certified": loop_decay(aug, X, K), "decay_spectral": spectral, "open_loop_decay": ol,
            "gain_ratio": nbk / na if na > 0 else float("inf")}  # fmt: skip


def unsaturated(X, K, u0, input_limits, region) -> dict | None:
    """Where the loop's certificate is not broken by its input limits: the largest level set
    ``E = {x : (x - x_c)^T X^-1 (x - x_c) <= c}`` of step 3's Lyapunov function (each rule's loop decreases it,
    (45) and the LMI 'decay' with X common to the rules, so E is invariant for the state feedback ``u = u0 +
    K_j (x - x_c)``) on which every input stays within its limits: ``c = min_i h_i^2 / max_j K_j,i X K_j,i^T``,
    ``h_i`` the distance of the input at rest ``u0`` (the input that holds ``x_c``) to its nearer limit, ``x_c``
    the reference state (0 without one). ``extent``: E's reach along each state, ``sqrt(c X_kk)``; ``fraction``: the smallest ratio of
    that reach to the plant's region's half-width (None where no state has finite bounds). The estimate is taken
    exact and the disturbances zero: the observer's error and the noise are not in it. None without input
    limits; ``{"headroom": ...}`` with a zero ``c`` where the input at rest is at or beyond a limit."""
    if input_limits is None:
        return None
    X = np.asarray(X, dtype=float)
    Ks = [np.asarray(k, dtype=float) for k in K]
    lim = np.asarray(input_limits, dtype=float)
    u0 = np.asarray(u0, dtype=float).ravel()
    head = np.minimum(lim[:, 1] - u0, u0 - lim[:, 0])
    spread = np.max([np.einsum("ik,kl,il->i", k, X, k) for k in Ks], axis=0)
    with np.errstate(divide="ignore"):
        c = float(np.min(np.where(spread > 0, np.maximum(head, 0.0) ** 2 / spread, np.inf)))
    extent = np.sqrt(c * np.diag(X)) if np.isfinite(c) else np.full(X.shape[0], np.inf)
    lo, hi = (np.asarray(region.get(side) or [], dtype=float) for side in ("lo", "hi"))
    half = 0.5 * (hi - lo) if lo.shape == hi.shape == extent.shape else np.full(extent.shape, np.nan)
    ok = np.isfinite(half) & (half > 0)
    return {
        "headroom": head.tolist(),
        "extent": [float(v) for v in extent],
        "region_half_width": [float(v) if ok[k] else None for k, v in enumerate(half)],
        "fraction": float(np.min(extent[ok] / half[ok])) if ok.any() else None,
    }


def recertify(d) -> list[str]:
    """What does not hold at the numbers of the design ``d`` (empty: certified): the stored matrices that are not
    what they are made of, then the certificate's failures (:func:`certify`, :func:`~.core._certify.failures`)."""
    aug = _augmented(d)
    out: list[str] = []
    T, H = np.asarray(d.T), np.asarray(d.H)
    point = _stored_point(d, aug)
    R = point["R"]
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
    acc = d.accommodation
    if (
        acc is not None and acc.get("rule") == "explain"
    ):  # the gate's ratios are the observer's own cross-talk
        from ._isolation import crosstalk

        made = crosstalk(R, T, aug.n, aug.lf)
        gap = _far(np.asarray(acc["crosstalk"], dtype=float), made)
        if (
            not gap <= _REL
            and _far(np.asarray(acc["crosstalk"], dtype=float), crosstalk(R, T, aug.n, aug.lf, False)) <= _REL
        ):
            out.append("accommodation.crosstalk is the observer's cross-talk at a fault's start only, as fte design "
                       "wrote it before 2026-11-29: it is no bound at a fault's end, where the gate then compensates "
                       f"the other faults' cross-talk (recomputed over both edges {np.round(made, 4).tolist()})")  # fmt: skip
        elif not gap <= _REL:
            out.append(f"accommodation.crosstalk is not the observer's cross-talk (off by {gap:.3g} relative; "
                       f"recomputed {np.round(made, 4).tolist()})")  # fmt: skip
        if "overshoot" in acc:  # and its overshoot and memory time the observer's own
            from ._isolation import overshoot

            ov, tau = overshoot(R, T, aug.n, aug.lf)
            gap = max(_far(np.asarray(acc["overshoot"], dtype=float), ov),
                      _far(np.array([float(acc.get("memory_time", np.nan))]), np.array([tau])))  # fmt: skip
            if not gap <= _REL:
                out.append(f"accommodation.overshoot and memory_time are not the observer's (off by {gap:.3g} "
                           f"relative; recomputed {np.round(ov, 4).tolist()}, {tau:.6g})")  # fmt: skip
            if "crosstalk_held" in acc:  # and the held estimates' ratios its own, at that memory time
                from ._isolation import crosstalk_held

                made = crosstalk_held(R, T, aug.n, aug.lf, tau)
                gap = _far(np.asarray(acc["crosstalk_held"], dtype=float), made)
                if not gap <= _REL:
                    out.append(f"accommodation.crosstalk_held is not the observer's cross-talk against the held "
                               f"estimates (off by {gap:.3g} relative; recomputed {np.round(made, 4).tolist()})")  # fmt: skip
    try:
        checks = certify(d)
    except np.linalg.LinAlgError as exc:
        return out + [f"the certificate cannot be evaluated at the loaded numbers ({exc})"]
    return out + _described(failed(checks), checks, aug, point)


def _described(bad: list[Failure], checks: dict, aug, point: dict) -> list[str]:
    """The failures of :func:`~.core._certify.failed` (the decision) in the words of a loaded document: the LMI's
    recomputed value, and the rule behind a non-Hurwitz matrix."""
    out = []
    for f in bad:
        if f.item in LMIS and f.item in checks["lmi_max_eig"]:
            name = LMIS[f.item].name(checks.get("theorem"))
            out.append(f"{name} recomputes to {checks['lmi_max_eig'][f.item]:+.3g} at the loaded numbers (balanced; it "
                       f"must be below -{checks['lmi_roundoff'][f.item]:.1g}, its round-off)")  # fmt: skip
        elif f.item == "R":
            for i, Ri in enumerate(point["R"]):
                top = float(np.max(np.linalg.eigvals(Ri).real))
                if not top < 0:
                    out.append(f"the observer matrix R_{i + 1} = T Abar_{i + 1} - L1_{i + 1} Cbar has an eigenvalue with "
                               f"real part {top:+.3g}")  # fmt: skip
        elif f.item == "closed_loop":
            for i in range(aug.r):
                for j in distinct(point["K"]):
                    A = aug.Abar[i][: aug.n, : aug.n] + aug.Bbar[i][: aug.n] @ point["K"][j]
                    top = float(np.max(np.linalg.eigvals(A).real))
                    if not top < 0:
                        out.append(f"the closed loop A_{i + 1} + B_{i + 1} K_{j + 1} has an eigenvalue with real part "
                                   f"{top:+.3g}")  # fmt: skip
        else:
            out.append(f.text)
    return out
