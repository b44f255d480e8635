"""A certified bound on the fault-estimation error of a returned design.

At the design's gains, the closed loop of the T-S model with the observer is, for ``xi = [x; e]``
(``e = xbar - xbarhat`` the augmented estimation error, ``f - fhat = J2 e``)::

    dx = [(A_i + B_i K_j) x - B_i (K_j J0 + Kf_j J2) e + Bd_i d + (B_i Kf_j + Bf_i) f + v_i] dt + W_i x dw
    de = [R_i e + J1 (f'' - u_s)] dt + T Wbar_i x dw

blended by ``h_i h_j`` (``v_i = B_i u_ref + a_i`` the constant input; ``T J1 = J1``, ``T Bdbar_i = 0``).
The error is driven by the fault's second derivative, the sliding term, and — through the state
— by the unknown input, the fault, the constant input and the diffusion ``W_i x dw``.

With ``w = [d; f''; u_s; f; 1]`` (the channels that are not identically zero), the stochastic
bounded-real lemma gives, for ``P > 0`` and ``g_k`` with, for every rule pair (i, j)::

    [[A_ij^T P + P A_ij + W_i^T P W_i + C^T C,  P B_ij ],
     [B_ij^T P,                                 -diag(g)]]  < 0,      C = [0, J2]

(affine in P and in the vertex matrices, so the vertices cover every blend of the rules; the diffusion's
``W_i^T P W_i`` is linear in P as it stands and is posed so: the Schur form with a ``-P`` block is the
same set for ``P > 0`` but twice the size, and a conic solver's cost per iteration grows like the cube of
each PSD cone's k(k+1)/2 rows; docs/benchmarks.md has the measurement), the bound

    E int_0^t |f - fhat|^2 ds  <=  sum_k g_k E int_0^t |w_k|^2 ds + E xi(0)^T P xi(0)

for every t, along the T-S model (the nonlinear plant inside the region where its T-S model is
exact) without input saturation. ``fault_error_bound`` solves ``min sum_k g_k`` (cvxpy), checks the
LMIs again with numpy at the returned point and records the per-channel gains ``sqrt(g_k)`` and P.
``state_error_bound`` does the same with the state-estimation error ``x - xhat = J0 e`` as the output
(``C = [0, J0]``), in numpy from scratch (phase 1, then the barrier method).
"""

from __future__ import annotations

import warnings

import numpy as np

__all__ = ["fault_error_bound"]  # public: docs/api.md

#: the input channels, in order
CHANNELS = ("d", "fddot", "u_s", "f", "const")
#: the analysis is skipped (and says so) beyond these sizes: one conic solve over all vertices, whose cost
#: grows with vertices x states^6 (measured, chain family, Clarabel: 20 closed-loop states and 4 vertices 1.8 s,
#: 16 states and 16 vertices 2.5 s, 64 vertices 12.6 s, 28 states 8 s, 36 states 21 s: a design of those takes
#: 1-6 s without it)
MAX_VERTICES, MAX_STATES = 16, 24


#: a sum whose terms cancel to this fraction of their size is zero (round-off, not a channel)
CANCELLED = 1e-9


def _cancelled(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``a + b``, or zeros when the two cancel to round-off: the fault channel ``B Kf + Bf`` of an actuator
    fault is zero in exact arithmetic, and a channel that exists or not by the last digits of the data would
    make the bound (and a design with it in the objective) jump under a 1e-12 change of the plant."""
    out = a + b
    if np.linalg.norm(out) <= CANCELLED * (np.linalg.norm(a) + np.linalg.norm(b)):
        return np.zeros_like(out)
    return out


def vertex_parts(design):
    """``([(i, j, Ax, channels, Wc)], Cz)``: the closed loop's vertices without the error's own dynamics
    (``Ax`` has a zero error block; the vertex matrix is ``Ax + diag(0, R_i)``). ``design`` needs
    ``dims.n, dims.lf, T, u_ref, K, Kf, Kf_rules, r, local_models`` (not R: step 5 poses the bound with
    R_i's ``Pbar R_i`` as an unknown)."""
    n, lf = int(design.dims.n), int(design.dims.lf)
    nbar = n + 2 * lf
    T = np.asarray(design.T, float)
    J0 = np.hstack([np.eye(n), np.zeros((n, 2 * lf))])
    J1 = np.vstack([np.zeros((n, lf)), np.eye(lf), np.zeros((lf, lf))])
    J2 = np.hstack([np.zeros((lf, n + lf)), np.eye(lf)])
    u_ref = np.asarray(design.u_ref, float).ravel()
    Kfs = list(design.Kf_rules) if design.Kf_rules is not None else [design.Kf] * design.r
    out = []
    for i, lm in enumerate(design.local_models):
        A, B, Bd, Bf, W = lm.A, lm.B, lm.Bd, lm.Bf, lm.W
        a = lm.a.ravel()
        Wbar = np.vstack([W, np.zeros((2 * lf, n))])
        Wc = np.block([[W, np.zeros((n, nbar))], [T @ Wbar, np.zeros((nbar, nbar))]])
        seen: list = []
        for j in range(design.r):
            K, Kf = np.asarray(design.K[j], float), np.asarray(Kfs[j], float)
            # vertex (i, j) depends on j only through K_j and Kf_j: with one common gain (the conditioned
            # design) the r^2 pairs are r distinct vertices
            if any(np.array_equal(K, K2) and np.array_equal(Kf, Kf2) for K2, Kf2 in seen):
                continue
            seen.append((K, Kf))
            Ax = np.block(
                [[A + B @ K, -B @ (K @ J0 + Kf @ J2)], [np.zeros((nbar, n)), np.zeros((nbar, nbar))]]
            )
            chans = {
                "d": np.vstack([Bd, np.zeros((nbar, Bd.shape[1]))]),
                "fddot": np.vstack([np.zeros((n, lf)), J1]),
                "u_s": np.vstack([np.zeros((n, lf)), -J1]),
                "f": np.vstack([_cancelled(B @ Kf, Bf), np.zeros((nbar, lf))]),
                "const": np.concatenate([_cancelled(B @ u_ref, a), np.zeros(nbar)])[:, None],
            }
            out.append((i, j, Ax, chans, Wc))
    Cz = np.hstack([np.zeros((lf, n)), J2])
    return out, Cz


def channel_names(verts) -> tuple[list, dict]:
    """The channels that are not identically zero at these vertices, and their sizes."""
    names = [c for c in CHANNELS if any(np.any(v[3][c]) for v in verts)]
    return names, {c: verts[0][3][c].shape[1] for c in names}


def _vertices(design):
    verts, Cz = vertex_parts(design)
    n = int(design.dims.n)
    out = []
    for i, j, Ax, chans, Wc in verts:
        Ac = Ax.copy()
        Ac[n:, n:] = np.asarray(design.R[i], float)
        out.append((i, j, Ac, chans, Wc))
    return out, Cz


def gain_diag(g, names, sizes) -> np.ndarray:
    """``diag(g_k I)`` over the channels ``names`` (each ``sizes[c]`` wide)."""
    return np.diag(np.concatenate([np.full(sizes[c], g[k]) for k, c in enumerate(names)]))


def _lmi(Ac, Bc, Wc, Cz, P, G):
    return np.block([
        [Ac.T @ P + P @ Ac + Wc.T @ P @ Wc + Cz.T @ Cz, P @ Bc],
        [Bc.T @ P, -G],
    ])  # fmt: skip


def _solve(verts, Cz, names, sizes, solver: str, schur: bool):
    """``min sum g`` over P, g (cvxpy): ``(P, g, status)``, None for a value the solver did not give.
    ``schur``: the diffusion term as the Schur complement of a ``-P`` block (the same set, twice the size)."""
    import cvxpy as cp

    from ._linalg import sym
    from ._sdp import SOLVER_SETTINGS, cvxpy_solver

    N = Cz.shape[1]
    P = cp.Variable((N, N), symmetric=True)
    g = cp.Variable(len(names))
    cons = [P >> 1e-9 * np.eye(N)]
    for _, _, Ac, chans, Wc in verts:
        Bc = np.hstack([chans[c] for c in names])
        Gd = cp.diag(cp.hstack([g[k] * np.ones(sizes[c]) for k, c in enumerate(names)]))
        if schur:
            k = Bc.shape[1]
            M = cp.bmat([
                [Ac.T @ P + P @ Ac + Cz.T @ Cz, P @ Bc, Wc.T @ P],
                [Bc.T @ P, -Gd, np.zeros((k, N))],
                [P @ Wc, np.zeros((N, k)), -P],
            ])  # fmt: skip
        else:
            M = cp.bmat([[Ac.T @ P + P @ Ac + Wc.T @ P @ Wc + Cz.T @ Cz, P @ Bc], [Bc.T @ P, -Gd]])
        cons.append(sym(M) << -1e-9 * np.eye(M.shape[0]))
    prob = cp.Problem(cp.Minimize(cp.sum(g)), cons)
    try:
        with warnings.catch_warnings():  # "may be inaccurate": the point is checked with numpy
            warnings.simplefilter("ignore", UserWarning)
            prob.solve(solver=cvxpy_solver(solver), **SOLVER_SETTINGS.get(solver, {}))
    except cp.error.SolverError as exc:
        del exc  # cvxpy's text ("Try another solver, or solve with verbose=True") is not advice for a user
        return None, None, f"{solver} failed numerically on the analysis LMI"
    if P.value is None or g.value is None:
        return None, None, f"the analysis LMI is {prob.status}"
    return sym(P.value), np.maximum(np.asarray(g.value, float), 0.0), prob.status


#: the factors by which g is raised, in turn, when the solver's point misses the LMIs by its round-off
REPAIR = (1e-8, 1e-6, 1e-4, 1e-3, 1e-2, 0.1, 0.5, 1.0, 2.0, 4.0)


def _checked(verts, Cz, names, sizes, Pv, gv):
    """The smallest ``g (1 + f)``, f in REPAIR (or f = 0), at which the LMIs hold at ``Pv`` (numpy), with the
    largest eigenvalue there; None when none does (a larger g only helps the g block)."""
    if np.linalg.eigvalsh(Pv)[0] <= 0:
        return None
    worst = np.inf
    for f in (0.0,) + REPAIR:
        gf = gv * (1.0 + f) + 1e-12 * (f > 0)
        G = gain_diag(gf, names, sizes)
        worst = max(
            float(np.linalg.eigvalsh(_lmi(Ac, np.hstack([ch[c] for c in names]), Wc, Cz, Pv, G))[-1])
            for _, _, Ac, ch, Wc in verts
        )
        if worst < 0:
            return gf, worst
    return None


#: the relative gap to which the analysis is centred in numpy from step 5's point (when the conic solver fails)
POINT_ETA = 1e-4


def _analysis(verts, Cz, names, sizes):
    """The analysis LMIs in numpy: ``(layout, soft, hard, c)`` with ``layout = (P, g)``, one LMI per vertex
    (``soft``), ``P > 0`` (``hard``) and the objective ``c`` of ``sum g``."""
    from ._sdp import Layout, Var, affine_lmi, positive

    N = Cz.shape[1]
    layout = Layout(Var("P", (N, N), True), Var("g", (len(names),)))

    def builder(Ac, Bc, Wc):
        return lambda P, g: _lmi(Ac, Bc, Wc, Cz, P, gain_diag(g, names, sizes))

    soft = [
        affine_lmi("bound", layout, builder(Ac, np.hstack([ch[c] for c in names]), Wc))
        for _, _, Ac, ch, Wc in verts
    ]
    c = np.zeros(layout.size)
    c[layout.index("g")] = 1.0
    return layout, soft, [positive(layout, "P")], c


def _from_point(verts, Cz, names, sizes, P0, g0):
    """``min sum g`` over a common P by the barrier method in numpy (:func:`~fte_casadi.design.core._barrier.centre`)
    from the strictly feasible ``(P0, g0)`` (step 5's block-diagonal certificate): ``(P, g)`` or ``(None, None)``."""
    from ...errors import CentringError
    from ._barrier import centre

    layout, soft, hard, c = _analysis(verts, Cz, names, sizes)
    try:
        cen = centre(soft + hard, c, layout.pack(P=P0, g=g0), eta=POINT_ETA)
    except CentringError:
        return None, None
    u = layout.unpack(cen.v)
    return u["P"], np.asarray(u["g"], float)


def _posed(design) -> tuple:
    """``(verts, Cz, None)`` of the closed loop, or ``(None, None, {"holds": False, "why"})`` where the analysis
    is not posed (Theorem 5's diffusion; beyond the size limits)."""
    if any(lm.has_diffusion_extension for lm in design.local_models):
        return None, None, {"holds": False, "why": "not computed for Theorem 5 diffusion (G, Gf, M)"}
    verts, Cz = _vertices(design)
    N = Cz.shape[1]
    if N > MAX_STATES or len(verts) > MAX_VERTICES:
        return None, None, {"holds": False, "why": f"not computed: {len(verts)} vertices of a closed loop of {N} "
                            f"states (the analysis is posed for at most {MAX_VERTICES} vertices and {MAX_STATES} states)"}  # fmt: skip
    return verts, Cz, None


def _record(found: tuple, err: str, structure: str, names: list, sizes: dict) -> dict:
    """The document's record of a bound on ``E int |err|^2 dt`` found at ``(P, g, worst)``."""
    Pv, gv, worst = found
    return {
        "holds": True,
        "what": f"E int |{err}|^2 dt <= sum_k gain_k^2 E int |w_k|^2 dt + E xi0' P xi0, xi = [x; xbar - xbarhat]",
        "P_structure": structure,
        "gains": {c: float(np.sqrt(gv[k])) for k, c in enumerate(names)},
        "channels": sizes,
        "P": Pv.tolist(),
        "lmi_max_eig": worst,
    }


def fault_error_bound(design, solver: str = "CLARABEL", fallback: dict | None = None) -> dict:
    """The bound of the module docstring at ``design``: ``{"holds", "gains": {channel: sqrt(g)},
    "channels": {channel: size}, "P": M, "lmi_max_eig", "what"}``; ``{"holds": False, "why"}`` when
    the analysis LMI is infeasible, fails its numpy check, or the design has Theorem 5 diffusion.

    The LMIs are posed with the diffusion term linear in P; when the solver gives no point that passes
    the numpy check there, the Schur form of the same set is solved too. When neither passes, ``fallback``
    (``{"P", "g", "names"}``: step 5's block-diagonal certificate, :mod:`~fte_casadi.design.core._bound_objective`)
    is checked the same way and recorded (``"P_structure": "block-diagonal"``); when that fails too, phase 1
    and centring in numpy (:func:`_from_scratch`) decide."""
    verts, Cz, why = _posed(design)
    if why:
        return why
    names, sizes = channel_names(verts)
    found, why, structure = None, "", "common"
    point = None
    if fallback is not None and list(fallback["names"]) == names:
        point = np.asarray(fallback["P"], float), np.asarray(fallback["g"], float)
        # step 5's point starts the barrier method in numpy: no conic solve, and the same answer on any machine
        Pv, gv = _from_point(verts, Cz, names, sizes, *point)
        ok = None if Pv is None else _checked(verts, Cz, names, sizes, Pv, gv)
        if ok is not None:
            found, structure = (Pv, *ok), "common (numpy, from step 5's block-diagonal point)"
    if found is None:
        found, why = _conic(verts, Cz, names, sizes, solver)
    if found is None and point is not None:
        ok = _checked(verts, Cz, names, sizes, *point)
        if ok is not None:
            found, structure = (point[0], *ok), "block-diagonal (step 5's)"
    if found is None:  # the conic solver failed or its point misses: phase 1 and centring in numpy decide
        found, how = _from_scratch(verts, Cz, names, sizes)
        if found is None:
            return {"holds": False, "why": f"{why}; {how}"}
        structure = f"common ({how}, where {solver} gave none)"
    return _record(found, "f - fhat", structure, names, sizes)


def _conic(verts, Cz, names, sizes, solver: str) -> tuple[tuple | None, str]:
    """``min sum g`` by the conic solver, the diffusion linear in P and then in Schur form: ``((P, g, worst),
    "")`` at the first point that passes the numpy check, or ``(None, why)``."""
    why = ""
    for schur in (False, True):
        Pv, gv, status = _solve(verts, Cz, names, sizes, solver, schur)
        ok = None if Pv is None else _checked(verts, Cz, names, sizes, Pv, gv)
        if ok is not None:
            return (Pv, *ok), ""
        why = status if Pv is None else "the analysis LMI does not hold at the solver's point"
    return None, why


def _from_scratch(verts, Cz, names, sizes, start=None) -> tuple[tuple | None, str]:
    """``min sum g`` in numpy without a feasible start point: phase 1 (:func:`~fte_casadi.design.core._barrier.phase1`,
    from ``start = (P, g)``, e.g. another output's certificate, or ``P = I``) finds a strictly feasible point
    or proves there is none, then the barrier method centres from it. ``((P, g, worst), how)`` at a point
    that passes the numpy check (the phase-1 point itself when the centring fails), or ``(None, why)``."""
    from ...errors import CentringError
    from ._barrier import centre, phase1

    layout, soft, hard, c = _analysis(verts, Cz, names, sizes)
    try:
        P0, g0 = (np.eye(Cz.shape[1]), np.ones(len(names))) if start is None else start
        v = phase1(soft, hard, layout.pack(P=P0, g=g0))
    except CentringError as exc:
        return None, f"phase 1 in numpy failed ({exc})"
    if v is None:
        return None, "the analysis LMI has no point (phase 1 in numpy)"
    how = "common (numpy, phase 1 and centring)"
    try:
        v = centre(soft + hard, c, v, eta=POINT_ETA).v
    except CentringError:
        how = "common (numpy, phase 1's point: the centring did not converge)"
    u = layout.unpack(v)
    ok = _checked(verts, Cz, names, sizes, u["P"], np.asarray(u["g"], float))
    if ok is None:
        return None, "the analysis LMI does not hold at the numpy point"
    return (u["P"], *ok), how


def state_error_bound(design, solver: str = "CLARABEL", start: dict | None = None) -> dict:
    """The bound of the module docstring with the state-estimation error ``x - xhat = J0 e`` as the output
    (``C = [0, J0]``): the same channels and LMIs, ``E int |x - xhat|^2 dt <= sum_k gain_k^2 E int |w_k|^2 dt
    + E xi0' P xi0``. Found in numpy (phase 1 and centring: no conic solve, the same answer on any machine),
    from ``start`` (the fault-error bound's dict, whose P satisfies these LMIs but for the output term) and
    then from ``P = I``; the conic solver when both fail. The same dict as :func:`fault_error_bound`."""
    verts, Cz, why = _posed(design)
    if why:
        return why
    n, N = int(design.dims.n), Cz.shape[1]
    Cx = np.hstack([np.zeros((n, n)), np.eye(n), np.zeros((n, N - 2 * n))])
    names, sizes = channel_names(verts)
    found, how = None, ""
    if start and start.get("holds") and list(start["gains"]) == names:
        P0 = np.asarray(start["P"], float)
        found, how = _from_scratch(
            verts, Cx, names, sizes, (P0, np.array([start["gains"][c] ** 2 for c in names]))
        )
    if found is None:
        found, how = _from_scratch(verts, Cx, names, sizes)
    if found is None:
        found, why = _conic(verts, Cx, names, sizes, solver)
        if found is None:
            return {"holds": False, "why": f"{how}; {why}"}
        how = f"common ({solver})"
    return _record(found, "x - xhat", how, names, sizes)


def bound_value(bounds: dict, energies: dict, v0: float) -> float:
    """The right side of the bound: ``sum_k gain_k^2 energies[k] + v0`` (``energies[k]`` the
    expected ``int |w_k|^2 dt`` of channel k, ``v0 = E xi0' P xi0``)."""
    return float(sum(bounds["gains"][c] ** 2 * energies.get(c, 0.0) for c in bounds["gains"]) + v0)
