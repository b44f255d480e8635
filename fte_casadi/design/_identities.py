"""The identities a loaded design's numbers must satisfy beside its certificate (:mod:`._recertify`).

The certificate speaks of ``X``, ``P``, ``Pbar``, ``Q``, ``theta``; the discrete step also runs on numbers the
LMIs do not constrain, or constrain only loosely, and each is made of the local models by a formula:

- ``Kf = -pinv(B_1) Bf_1`` and, where the rules' gains differ, ``Kf_rules[i] = -pinv(B_i) Bf_i`` (a negated Kf
  still certifies, and makes tolerant control worse than none);
- ``H`` of (17), and ``T Bdbar_i = 0`` (the unknown inputs decoupled); with Remark 5's fallback, ``T Bdbar_i``
  in the span of the undecoupled directions, ``H Cbar H = H`` and ``H`` in the span of the ``Bdbar_i``;
- ``N = J1^T T^T Pbar Cbar^+`` where the conditioned variant made it (the paper variant solves for N, and the
  LMIs (55), (64) constrain it);
- ``checks.ts_max``, the largest sample time the C generator allows, is that of the observer matrices ``R_i``.

:func:`identity_failures` lists what does not hold, each a phrase naming the matrix and how far it is off.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from ._augment import augment
from ._uio import uio_gain
from .core._certify import ts_max

__all__ = []  # internal: fte_casadi.trust calls it on load

#: how far (relative) a stored matrix may be from what it is made of: the design writes 17 significant
#: digits, so anything above round-off is an edit (the same bound as the certificate's rebuilt matrices)
REL = 1e-6
#: how far from zero ``T Bdbar_i`` may be, relative to ``|T| |Bdbar_i|``: round-off of the product
DECOUPLED = 1e-9


def _far(stored: np.ndarray, made: np.ndarray) -> float:
    """``max |stored - made|`` relative to the larger of the two (0 for empty matrices)."""
    if made.size == 0:
        return 0.0
    scale = max(float(np.max(np.abs(made))), float(np.max(np.abs(stored))), 1e-300)
    return float(np.max(np.abs(stored - made))) / scale


def _fault_gains(d) -> list[str]:
    """Kf and Kf_rules against ``-pinv(B_i) Bf_i`` of the loaded local models."""
    made = [-np.linalg.pinv(lm.B) @ lm.Bf for lm in d.local_models]
    out = []
    gap = _far(np.asarray(d.Kf, float), made[0])
    if not gap <= REL:
        out.append(f"Kf is not -pinv(B_1) Bf_1 (off by {gap:.3g} relative)")
    spread = max(_far(Ki, made[0]) for Ki in made)
    if d.Kf_rules is None:
        if spread > REL:
            out.append(f"the rules' fault gains -pinv(B_i) Bf_i differ (by {spread:.3g} relative) but the document has "
                       "no Kf_rules: the step would compensate every rule's faults with rule 1's Kf")  # fmt: skip
        return out
    for i, (Ki, Mi) in enumerate(zip(d.Kf_rules, made)):
        gap = _far(np.asarray(Ki, float), Mi)
        if not gap <= REL:
            out.append(f"Kf_rules[{i}] is not -pinv(B_{i + 1}) Bf_{i + 1} (off by {gap:.3g} relative)")
    return out


def _decoupling(d, aug) -> list[str]:
    """H of (17) and the decoupling ``T Bdbar_i = 0`` (Remark 5: ``T Bdbar_i`` in the span of ``Bdu``)."""
    out = []
    H, T = np.asarray(d.H, float), np.asarray(d.T, float)
    Bd = [np.asarray(B, float) for B in aug.Bdbar]
    if not d.remark5.get("used"):
        gap = _far(H, uio_gain(aug)[0])
        if not gap <= REL:
            out.append(
                f"H is not the unknown-input gain (17) of the local models (off by {gap:.3g} relative)"
            )
        left = np.eye(aug.nbar)
    else:
        Bdu = np.asarray(d.remark5["Bdu"], float)
        left = np.eye(aug.nbar) - Bdu @ np.linalg.pinv(Bdu)  # what is not an undecoupled direction
        gap = _far(H @ aug.Cbar @ H, H)
        if not gap <= REL:
            out.append(f"H Cbar H is not H (off by {gap:.3g} relative): H Cbar is no projection")
        stacked = np.hstack(Bd)
        if stacked.size and np.any(H):
            outside = H - stacked @ np.linalg.pinv(stacked) @ H
            gap = float(np.max(np.abs(outside))) / float(np.max(np.abs(H)))
            if not gap <= REL:
                out.append(f"H has columns outside the span of the unknown inputs' directions Bdbar_i (off by "
                           f"{gap:.3g} relative)")  # fmt: skip
    for i, B in enumerate(Bd):
        if not B.size:
            continue
        resid = left @ T @ B
        top = float(np.max(np.abs(resid)))
        scale = max(1.0, float(np.max(np.abs(T)))) * float(np.max(np.abs(B)))
        if not top <= DECOUPLED * scale:
            what = "T Bd" if not d.remark5.get("used") else "T Bd outside the undecoupled directions Bdu"
            out.append(f"{what}_{i + 1} is not 0: max |{what.split(' outside')[0]}_{i + 1}| = {top:.3g} (the unknown "
                       f"inputs are not decoupled; {DECOUPLED:g} x {scale:.3g} allowed)")  # fmt: skip
    return out


def _sliding_gain(d, aug) -> list[str]:
    """N = J1^T T^T Pbar Cbar^+ where the conditioned variant made it."""
    if d.variant != "conditioned":
        return []
    made = aug.Js.T @ np.asarray(d.T, float).T @ np.asarray(d.Pbar, float) @ np.linalg.pinv(aug.Cbar)
    gap = _far(np.asarray(d.N, float), made)
    if not gap <= REL:
        return [
            f"N is not J1^T T^T Pbar Cbar^+ (off by {gap:.3g} relative), as the conditioned variant makes it"
        ]
    return []


def _largest_sample_time(d, aug) -> list[str]:
    """checks.ts_max against the largest stable sample time of ``R_i = T Abar_i - L1_i Cbar``."""
    stored = d.checks.get("ts_max") if isinstance(d.checks, dict) else None
    if stored is None:
        return []
    T = np.asarray(d.T, float)
    R = [T @ aug.Abar[i] - np.asarray(d.L1[i], float) @ aug.Cbar for i in range(aug.r)]
    made = ts_max(R)
    stored = float(stored)
    same = stored == made or (np.isfinite(made) and abs(stored - made) <= REL * max(abs(made), 1e-300))
    if not same:
        return [f"checks.ts_max is {stored:.6g} but the observer matrices R_i give {made:.6g} (the largest sample "
                "time the generated C may run at)"]  # fmt: skip
    return []


def identity_failures(d) -> list[str]:
    """What of the identities above does not hold at the numbers of the design ``d`` (empty: all hold)."""
    aug = augment(d.local_models, d.C, d.Df)
    if d.remark5.get("used"):
        aug = dataclasses.replace(aug, Jd=np.asarray(d.remark5["Bdu"], dtype=float))
    try:
        return _fault_gains(d) + _decoupling(d, aug) + _sliding_gain(d, aug) + _largest_sample_time(d, aug)
    except np.linalg.LinAlgError as exc:
        return [f"the identities of Kf, H and N cannot be evaluated at the loaded numbers ({exc})"]
