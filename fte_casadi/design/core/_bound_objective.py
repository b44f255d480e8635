"""The closed loop's fault-error bound as a term of step 5's objective.

:mod:`fte_casadi.design.core._bounds` certifies, at a returned design, the gain from the channels
``w = [d; f''; u_s; f; 1]`` to ``f - fhat`` with one common Lyapunov matrix ``P`` of the closed loop
``xi = [x; e]``. Here the same stochastic bounded-real LMI is posed *inside* step 5, where the observer
is still an unknown, with a block-diagonal ``P = diag(P1, lam Pbar)``: with step 3's gain ``K`` fixed and
the scale ``lam`` fixed per design, every term is then affine in step 5's unknowns. In step 5's homogenised
variables (``Pbar = Pt / s``, ``Q_i = rho_i Cbar^T / (2 s)``) the LMI times ``s / lam`` reads, per vertex
(rule i, gain j)::

    [[He(P' Ax_ij) + diag(0, He(Pt T Abar_i - rho_i Cbar^T Cbar / 2)) + Wc_i^T P' Wc_i + (s / lam) Cz^T Cz,  P' Bc_ij],
     [.,                                                                                                   -diag(g')]]  < 0

with ``P' = diag(P1', Pt)``, ``P1' = s P1 / lam > 0`` and ``g' = s g / lam`` (``g`` the squared gains);
``Ax_ij`` is the closed loop without the error's own dynamics (:func:`~fte_casadi.design.core._bounds.vertex_parts`).
``lam`` is twice the smallest scale at which the error's block alone holds at the design without the term
(a generalised eigenvalue; with ``lam = 1`` the three-tank's has no point). The
block-diagonal ``P`` is a restriction of the certified bound's common ``P``, so this term is an upper
bound of the certified one (which is computed afterwards, as for every design).

The term enters the centring's objective as ``weight * (c^T v*) / (sum g'*) * sum g'`` where ``v*`` is
the design without it and ``g'*`` the smallest ``g'`` at ``v*``'s observer: ``weight = 1`` makes the bound
count as much as the rest of step 5's objective (gain scales and sliding mismatch) did at the design
without it, whatever the plant's units. Four centrings in numpy, each unique (the design stays a
function of the data): the design without the term, the smallest ``g'`` at its observer (``P1'`` and
``g'`` only, to a relative gap of REF_ETA), the design with the term from there, and the smallest ``g'``
at the new observer, which is reported (``sum_k g_k`` before and after) and is a certificate of the
bound in its own right: the design's ``bounds`` fall back on it when the analysis with a common P
gives no point that passes its check.
"""

from __future__ import annotations

import numpy as np

from ...errors import CentringError
from ._barrier import centre, phase1
from ._bounds import MAX_STATES, MAX_VERTICES, channel_names, gain_diag, vertex_parts
from ._sdp import AffineLMI, Layout, Var, affine_lmi, positive

__all__ = []  # public: docs/api.md


def _padded(L: AffineLMI, extra: int) -> AffineLMI:
    """``L`` on a layout with ``extra`` unknowns appended (which it does not involve)."""
    k = L.k
    G = None if L.G is None else np.concatenate([L.G, np.zeros((extra, k, k))])
    return AffineLMI(L.name, L.F0, np.concatenate([L.F, np.zeros((extra, k, k))]), G, L.kron, L.kron_G)


def _restricted(L: AffineLMI, v: np.ndarray, free: np.ndarray) -> AffineLMI:
    """``L`` with every unknown but ``free`` fixed at its value in ``v``."""
    fixed = np.setdiff1d(np.arange(len(v)), free)
    return AffineLMI(L.name, L.F0 + np.tensordot(v[fixed], L.F[fixed], 1), L.F[free])


def _block(L: AffineLMI, rows: np.ndarray) -> AffineLMI:
    """The principal block ``rows`` of ``L``."""
    ix = np.ix_(rows, rows)
    return AffineLMI(L.name, L.F0[ix], L.F[(slice(None), *ix)])


class BoundTerm:
    """The bound LMIs on step 5's layout extended by ``P1'`` and ``g'``, and the centring with them
    (``verts, Cz``: :func:`~fte_casadi.design.core._bounds.vertex_parts` of the closed loop)."""

    def __init__(self, layout: Layout, aug, T, P, verts, Cz, weight: float):
        self.names, self.sizes = channel_names(verts)
        n, nbar = aug.n, aug.nbar
        self.base = layout
        self.layout = Layout(*layout.vars, Var("P1", (n, n), True), Var("g", (len(self.names),)))
        self.extra = self.layout.size - layout.size
        self.weight = float(weight)
        self.P = np.asarray(P, float)
        Cb = aug.Cbar
        CtC = Cb.T @ Cb
        TA = [T @ A for A in aug.Abar]
        N = n + nbar
        self.N, self.n = N, n

        def builder(i, Ax, Bc, Wc):  # without the output term s Cz^T Cz / lam (added per lam: _scaled)
            def f(Pt, s, rho, tau, P1, g):
                Pp = np.zeros((N, N))
                Pp[:n, :n], Pp[n:, n:] = P1, Pt
                PA = Pp @ Ax
                PA[n:, n:] += Pt @ TA[i] - rho[i] * CtC / 2
                M11 = PA + PA.T + Wc.T @ Pp @ Wc
                G = gain_diag(g, self.names, self.sizes)
                return np.block([[M11, Pp @ Bc], [(Pp @ Bc).T, -G]])

            return f

        self.raw = []
        for i, j, Ax, chans, Wc in verts:
            Bc = np.hstack([chans[c] for c in self.names])
            sup = self.layout.support("Pt", ("rho", i), "P1", "g")
            self.raw.append(affine_lmi(f"bound, rule {i + 1} gain {j + 1}", self.layout, builder(i, Ax, Bc, Wc),
                                       support=sup))  # fmt: skip
        k = self.raw[0].k
        self.out = np.zeros((k, k))
        self.out[:N, :N] = Cz.T @ Cz
        self.lam = 1.0
        self.lmis = self.raw
        self.positive = positive(self.layout, "P1")
        self.free = np.r_[self.layout.support("P1"), self.layout.support("g")]
        self.notes: list[str] = []
        self.newton = 0

    def _scaled(self, lam: float) -> list[AffineLMI]:
        """The bound LMIs with the output term ``(s / lam) Cz^T Cz``: ``P = lam diag(P1', Pt) / s``, ``g = lam g' / s``."""
        i_s = self.base.index("s").start
        out = []
        for L in self.raw:
            F = L.F.copy()
            F[i_s] += self.out / lam
            out.append(AffineLMI(L.name, L.F0, F))
        return out

    def _lam(self, v: np.ndarray) -> float | None:
        """The scale of the error's block: ``P = diag(P1, lam Pbar)`` needs ``He(Pbar R_i) + J2^T J2 / lam < 0``,
        whose smallest ``lam`` is a generalised eigenvalue at ``v``'s observer; twice that (None when some
        ``He(Pbar R_i)`` is not negative definite)."""
        ext = np.concatenate([v, np.zeros(self.extra)])
        s = float(v[self.base.index("s").start])
        e = slice(self.n, self.N)
        lam0 = 0.0
        for L in self.raw:
            M = -L.value(ext)[e, e]
            try:
                Li = np.linalg.inv(np.linalg.cholesky(M))
            except np.linalg.LinAlgError:
                return None
            lam0 = max(lam0, float(np.linalg.eigvalsh(Li @ (s * self.out[e, e]) @ Li.T)[-1]))
        return 2.0 * lam0 if lam0 > 0 else 1.0

    def _start(self, v: np.ndarray) -> np.ndarray | None:
        """``v`` with ``P1'`` and ``g'`` strictly feasible for the bound LMIs at ``v``'s observer, or None; sets
        the error block's scale ``lam`` (doubled up to LAM_TRIES times while phase 1 finds no ``P1'``)."""
        lam = self._lam(v)
        if lam is None:
            return None
        ext = np.concatenate([v, np.zeros(self.extra)])
        Pt = self.base.unpack(v)["Pt"]
        u = self.layout.unpack(ext)
        u["P1"] = self.P * (np.linalg.norm(Pt, 2) / np.linalg.norm(self.P, 2))
        ext = self.layout.pack(**u)
        rows = np.arange(self.N)
        ip = self.layout.support("P1")
        # the g block holds for g large enough iff the upper-left block (the closed loop's Lyapunov inequality
        # with the output term) does: phase 1 on that block in P1' alone, then g' from its Schur complement
        for _ in range(LAM_TRIES):
            lmis = self._scaled(lam)
            soft = [_restricted(_block(L, rows), ext, ip) for L in lmis]
            w = phase1(soft, [_restricted(self.positive, ext, ip)], ext[ip])
            if w is not None:
                break
            lam *= 4.0
        else:
            return None
        self.lam, self.lmis = lam, lmis
        ext[ip] = w
        need = 0.0
        for L in self.lmis:
            M = L.value(ext)
            M11, M12 = M[: self.N, : self.N], M[: self.N, self.N :]
            need = max(need, float(np.linalg.norm(M12, 2)) ** 2 / -float(np.linalg.eigvalsh(M11)[-1]))
        ext[self.layout.index("g")] = 2.0 * need + 1e-12
        return ext

    def _smallest(self, ext: np.ndarray) -> tuple[np.ndarray, float]:
        """``ext`` with ``P1'``, ``g'`` at (within REF_ETA of) the smallest ``sum g'`` at ``ext``'s observer, from
        ``ext``'s own (strictly feasible) ones; and that ``sum g``, in the design's units (``g = lam g' / s``)."""
        cg = np.zeros(self.layout.size)
        cg[self.layout.index("g")] = 1.0
        sub = [_restricted(L, ext, self.free) for L in self.lmis + [self.positive]]
        cen = centre(sub, cg[self.free], ext[self.free], eta=REF_ETA)
        out = ext.copy()
        out[self.free] = cen.v
        s = float(out[self.base.index("s").start])
        self.newton += cen.newton_steps
        return out, self.lam * float(np.sum(out[self.layout.index("g")])) / s

    def improve(self, lmis: list, c: np.ndarray, v: np.ndarray, eta: float) -> tuple[np.ndarray, dict] | None:
        """The design with the bound in the objective, from the centred design ``v`` without it (``lmis`` its
        LMIs at the decay rate, ``c`` its objective): ``(v_extended, info)``, or None (said in ``notes``)
        when the bound LMIs with a block-diagonal P have no point at ``v``'s observer or a centring fails.
        ``info``: the weight, the smallest ``sum_k g_k`` at the observer without and with the term, and the
        certificate at the latter (``P = diag(P1, lam Pbar)``, ``g``)."""
        self.newton = 0
        try:
            ext = self._start(v)
            if ext is None:
                self.notes.append("the closed-loop bound with a block-diagonal P = diag(P1, lam Pbar) has no point "
                                  "at this design's observer: left out of the objective")  # fmt: skip
                return None
            ext, before = self._smallest(ext)
            ig = self.layout.index("g")
            scale = self.weight * float(c @ v) / float(np.sum(ext[ig]))
            c2 = np.concatenate([c, np.zeros(self.extra)])
            c2[ig] = scale
            full = [_padded(L, self.extra) for L in lmis] + self.lmis + [self.positive]
            cen = centre(full, c2, ext, eta=eta)
            self.newton += cen.newton_steps
            out, after = self._smallest(cen.v)
        except CentringError as exc:
            self.notes.append(
                f"the centring with the closed-loop bound failed ({exc}): left out of the objective"
            )
            return None
        u = self.layout.unpack(out)
        k = self.lam / u["s"]
        Pc = np.zeros((self.N, self.N))
        Pc[: self.n, : self.n], Pc[self.n :, self.n :] = k * u["P1"], k * u["Pt"]
        info = {"weight": self.weight, "before": before, "after": after, "newton_steps": self.newton,
                "P": Pc, "g": k * np.asarray(u["g"], float), "names": list(self.names)}  # fmt: skip
        return out, info


#: the relative gap of the smallest bound at a given observer (the reference of the weight, and what is reported)
REF_ETA = 1e-3
#: how many times the error block's scale is raised (x4) when phase 1 finds no P1 at the first
LAM_TRIES = 3


def bound_term(layout: Layout, aug, T, P, view, weight) -> tuple[BoundTerm | None, str]:
    """The term for step 5, or None with the reason it is not used."""
    if not weight:
        return None, ""
    if view is None:
        return (
            None,
            "the closed-loop bound is not posed for this design (Remark 5's fallback or Theorem 5's diffusion)",
        )
    verts, Cz = vertex_parts(view)
    N = Cz.shape[1]
    if N > MAX_STATES or len(verts) > MAX_VERTICES:
        return None, (f"the closed-loop bound is left out of step 5's objective: {len(verts)} vertices of a closed "
                      f"loop of {N} states (posed for at most {MAX_VERTICES} vertices and {MAX_STATES} states)")  # fmt: skip
    return BoundTerm(layout, aug, T, P, verts, Cz, weight), ""
