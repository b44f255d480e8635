"""python-control interop: local models and local closed loops as ``control.StateSpace`` objects.

python-control is an optional dependency (``pip install 'fte_casadi[control]'``); every function
here imports it on call and says so clearly when it is missing. Used by
:meth:`fte_casadi.ts.TSModel.to_control` and :meth:`fte_casadi.design.Design.to_control`.
"""

from __future__ import annotations

import numpy as np
import scipy.linalg as sla

from .errors import MissingDependencyError

__all__ = ["require_control", "local_model_ss", "closed_loop_ss"]


def require_control():
    """The ``control`` module, or a :class:`MissingDependencyError` that says how to install it."""
    try:
        import control
    except ImportError:
        raise MissingDependencyError(
            "python-control is not installed; install the optional extra: pip install 'fte_casadi[control]'"
        ) from None
    return control


def local_model_ss(lm, C, Df, names: dict, rule: int, plant: str):
    """``dx = A x + B u + Bd d + Bf f``, ``y = C x + Df f`` of one rule (affine offset and diffusion left out)."""
    ct = require_control()
    m, ld = lm.B.shape[1], lm.Bd.shape[1]
    p = C.shape[0]
    B = np.hstack([lm.B, lm.Bd, lm.Bf])
    D = np.hstack([np.zeros((p, m + ld)), Df])
    return ct.ss(
        lm.A, B, C, D,
        inputs=names["inputs"] + names["unknown_inputs"] + names["faults"],
        outputs=names["outputs"], states=names["states"], name=f"{plant}_rule{rule + 1}",
    )  # fmt: skip


def closed_loop_ss(design, i: int, j: int, sample_time: float | None = None):
    """Plant rule ``i``, observer rule ``i`` and controller gain ``K_j`` in closed loop (see Design.to_control)."""
    ct = require_control()
    dims = design.dims
    n, m, p, lf, nbar, r = (int(v) for v in (dims.n, dims.m, dims.p, dims.lf, dims.nbar, dims.r))
    for nm, k in (("i", i), ("j", j)):
        if not (isinstance(k, (int, np.integer)) and 0 <= k < r):
            from .errors import ParameterError

            raise ParameterError(f"rule index {nm} must be an integer in 0..{r - 1}; got {k!r}")
    lm = design.local_models[i]
    A, B, Bd, Bf = lm.A, lm.B, lm.Bd, lm.Bf
    C, Df, H, T = (np.asarray(a, float) for a in (design.C, design.Df, design.H, design.T))
    ld = Bd.shape[1]
    R = np.asarray(design.R[i], float)
    Ly = np.asarray(design.L1[i], float) + np.asarray(design.L2[i], float)
    TB = T @ np.vstack([B, np.zeros((2 * lf, m))])
    J0 = np.hstack([np.eye(n), np.zeros((n, 2 * lf))])
    J2 = np.hstack([np.zeros((lf, n + lf)), np.eye(lf)])
    M = np.asarray(design.K[j], float) @ J0 + design.kf(j) @ J2  # u = r + M xbarhat
    # xbarhat = z + H y, y = C x + Df f, u = r + M xbarhat: inputs [r; d; f], states [x; z]
    Uz, Ux, Uf = M, M @ H @ C, M @ H @ Df
    Gx = np.hstack([B, Bd, Bf])  # how [u; d; f] enters the plant
    if sample_time is None:
        Ad, Gd = A, Gx
        Az, Gz, Lz = R, TB, Ly
    else:
        if not (isinstance(sample_time, (int, float)) and np.isfinite(sample_time) and sample_time > 0):
            from .errors import ParameterError

            raise ParameterError(f"sample_time must be a positive number; got {sample_time!r}")
        E = sla.expm(np.block([[A, Gx], [np.zeros((Gx.shape[1], n + Gx.shape[1]))]]) * sample_time)
        Ad, Gd = E[:n, :n], E[:n, n:]  # zero-order hold of the plant
        Az, Gz, Lz = (
            np.eye(nbar) + sample_time * R,
            sample_time * TB,
            sample_time * Ly,
        )  # the observer as the C computes it
    Bu, Bdd, Bff = Gd[:, :m], Gd[:, m : m + ld], Gd[:, m + ld :]
    Acl = np.block([[Ad + Bu @ Ux, Bu @ Uz], [Lz @ C + Gz @ Ux, Az + Gz @ Uz]])
    Bcl = np.block([[Bu, Bdd, Bff + Bu @ Uf], [Gz, np.zeros((nbar, ld)), Lz @ Df + Gz @ Uf]])
    Ccl = np.block([[C, np.zeros((p, nbar))], [Ux, Uz], [H @ C, np.eye(nbar)]])
    Dcl = np.block([[np.zeros((p, m + ld)), Df], [np.eye(m), np.zeros((m, ld)), Uf],
                    [np.zeros((nbar, m + ld)), H @ Df]])  # fmt: skip
    names = design.names or {}
    un = names.get("inputs") or [f"u{k}" for k in range(m)]
    yn = names.get("outputs") or [f"y{k}" for k in range(p)]
    xn = names.get("states") or [f"x{k}" for k in range(n)]
    fn = names.get("faults") or [f"f{k}" for k in range(lf)]
    xbar = [f"{s}_hat" for s in xn] + [f"{s}_dot_hat" for s in fn] + [f"{s}_hat" for s in fn]
    return ct.ss(
        Acl, Bcl, Ccl, Dcl, sample_time if sample_time is not None else 0,
        inputs=[f"{s}_ref" for s in un] + [f"d{k}" for k in range(ld)] + list(fn),
        outputs=list(yn) + list(un) + xbar,
        states=list(xn) + [f"z{k}" for k in range(nbar)],
        name=f"{design.plant}_loop_rule{i + 1}_gain{j + 1}",
    )  # fmt: skip
