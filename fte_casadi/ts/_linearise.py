"""T-S models by local linearisation at operating points, with triangular memberships.

Affine offsets: a Jacobian taken at ``(x_k, u_k)`` gives ``f(x, u) ~ A_k x + B_k u + a_k`` with
``a_k = f(x_k, u_k) - A_k x_k - B_k u_k``. The offset does not vanish even at an equilibrium
(``f(x_k, u_k) = 0`` leaves ``a_k = -(A_k x_k + B_k u_k)``), so dropping it — as the paper's
``A_i x + B_i u`` does — would feed the observer a constant model error of the size of the
flows themselves. fte_casadi keeps ``a_k`` in each local model and the observer adds the known
blended term ``T sum_i h_i [a_i; 0; 0]``; the error dynamics, and hence the LMIs, are unchanged.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from ..model import Plant
from ._memberships import triangular_membership_fn
from ._model import LocalModel, Premise

__all__ = ["linearised_local_models"]


def linearised_local_models(plant: Plant):
    x, u, d, f, d2, z = plant.x, plant.u, plant.d, plant.f, plant.d2, plant.z
    fz, gz = plant.drift_z, plant.diffusion_z
    outs = [
        fz,
        ca.jacobian(fz, x),
        ca.jacobian(fz, u),
        ca.jacobian(fz, d) if d.numel() else ca.SX(plant.n, 0),
        ca.jacobian(fz, f),
        gz,
        ca.jacobian(gz, x),
        ca.jacobian(gz, u),
        ca.jacobian(gz, f),
        ca.jacobian(gz, d2) if d2.numel() else ca.SX(plant.n, 0),
    ]
    F = ca.Function("lin", [x, u, d, f, d2, z], outs)
    r = plant.operating_points.shape[0]
    models = []
    for k in range(r):
        xk, uk = plant.operating_points[k], plant.operating_inputs[k]
        vals = [
            np.array(v, dtype=float)
            for v in F(
                xk, uk, np.zeros(plant.ld), np.zeros(plant.lf), np.zeros(plant.d2.numel()), np.eye(r)[k]
            )
        ]
        f0, A, B, Bd, Bf, _g0, W, G, Gf, M = vals
        a = f0.ravel() - A @ xk - B @ uk
        models.append(
            LocalModel(
                A=A, B=B, Bd=Bd.reshape(plant.n, -1), Bf=Bf, W=W, a=a, G=G, Gf=Gf, M=M.reshape(plant.n, -1)
            )
        )
    j = plant.scheduling_state
    centres = plant.operating_points[:, j]
    name = plant.state_names[j]
    premise = Premise(name, name, float(centres[0]), float(centres[-1]), (j,), 0.0)
    premise_fn = ca.Function("premises", [x], [x[j]], ["x"], ["premises"])
    return (premise,), tuple(models), premise_fn, triangular_membership_fn(centres)
