"""The discrete observer/controller step as ONE CasADi Function (docs/method.md, "The discrete step").

This Function is the single source of truth: the Monte Carlo engine maps it over paths and the
C generator exports it, so simulation and embedded code cannot drift apart. At sample k, with
measurement ``y`` and observer state ``z``::

    xbarhat = z + H y                                   = [xhat; fdothat; fhat]
    h       = h(y, xhat)                                memberships from measured signals
    s       = N (y - Cbar xbarhat),  us = g .* sgn(s)   (or a boundary layer); g = delta + eps,
                                                         with Remark 5 first the gains of the undecoupled d
    u       = sat(u_ref + sum_j h_j (K_j xhat + Kf_j G fhat)) (no Kf term without tolerant control;
                                                         G = I, or diag(accommodation_gate) of the design,
                                                         whose latches, with a release ratio < 1, follow
                                                         z in the state: z+ then ends with G's diagonal;
                                                         Kf_j = Kf unless the rules' Kf_i differ;
                                                         sat: the actuator limits, if any)
    yc      = y - Df fhat                               (y itself without tolerant control)
    z+      = z + Ts sum_i h_i (R_i z + T Bbar_i u + (L_i1 + L_i2) y + Ls us + T abar_i)

``abar_i = [a_i; 0; 0]`` is the affine offset of a linearised local model (zero for sector
models; see :mod:`fte_casadi.ts._linearise`). The sum over rules is expanded (one product per
rule and signal), not blended into a matrix per sample: that is fewer operations for the
small rule counts of T-S models and what a hand-written loop would do.
"""

from __future__ import annotations

import casadi as ca
import numpy as np

from .design import Design
from .errors import ParameterError

__all__ = ["step_function", "saturate", "StepParameters", "STEP_INPUTS", "STEP_OUTPUTS"]

STEP_INPUTS = ("z", "y")
STEP_OUTPUTS = ("z_next", "u", "xbarhat", "yc", "s")


def _dm(a: np.ndarray) -> ca.DM:
    return ca.DM(np.asarray(a, dtype=float))


class _Folded:
    """The design's numbers folded into the step as constants (the default: the generated C)."""

    def matrix(self, name: str, a) -> ca.DM:
        return _dm(a)

    def scalar(self, name: str, v) -> float:
        return float(v)


class StepParameters:
    """The design's numbers as the entries of one parameter vector, not constants: a step built with it
    computes the same numbers, and its Function's structure depends on the design's shapes, its zeros and
    which of its numbers are equal, not on their values (the simulation compiles one engine per structure,
    not per design: ``fte tune``'s trials share one).

    One symbol per distinct value (an observer's rules share most of their entries, and the products that
    constants would share stay shared); zeros and ones stay constants (``0 * x`` and ``1 * x`` are
    simplified away as they are with constants). A name asked again gets the same matrix (the tolerant and
    the plain step of one closed loop). :attr:`symbols`: the vector of the symbols (a Function's input),
    :attr:`values`: its value. The numbers computed are those of the step with constants, to the bit."""

    def __init__(self):
        self._by_value: dict[float, ca.SX] = {}  # in order of creation: the parameter vector's entries
        self._made: dict[str, tuple[object, np.ndarray]] = {}

    def _entry(self, v: float):
        if v in (0.0, 1.0, -1.0):
            return v
        sym = self._by_value.get(v)
        if sym is None:
            sym = self._by_value[v] = ca.SX.sym(f"p{len(self._by_value)}")
        return sym

    def _memo(self, name: str, a: np.ndarray):
        made = self._made.get(name)
        if made is not None and not np.array_equal(made[1], a):
            raise ValueError(f"step parameter {name!r} given two different values")
        return None if made is None else made[0]

    def matrix(self, name: str, a) -> ca.SX:
        a = np.asarray(a, dtype=float)
        a = a.reshape(-1, 1) if a.ndim < 2 else a
        out = self._memo(name, a)
        if out is None:
            out = ca.SX.zeros(a.shape[0], a.shape[1])  # dense, as a DM of the matrix is: zeros are constants
            for i, j in zip(*np.nonzero(a)):
                out[int(i), int(j)] = self._entry(float(a[i, j]))
            self._made[name] = (out, a)
        return out

    def scalar(self, name: str, v) -> ca.SX:
        a = np.array([[float(v)]])
        out = self._memo(name, a)
        if out is None:
            out = ca.SX(self._entry(float(v)))
            self._made[name] = (out, a)
        return out

    @property
    def symbols(self) -> ca.SX:
        return ca.vertcat(*self._by_value.values()) if self._by_value else ca.SX(0, 1)

    @property
    def values(self) -> np.ndarray:
        return np.array(list(self._by_value), dtype=float)


def saturate(u: ca.SX, limits) -> ca.SX:
    """``u`` clipped into the actuator limits (rows [lo, hi]; infinite sides left open).

    The clipped input is what the step returns, what the plant receives and what the observer
    update uses (``T Bbar_i u``): the observer is fed the input actually applied.
    """
    if limits is None:
        return u
    lim = np.asarray(limits, dtype=float)
    out = []
    for k in range(u.numel()):
        uk = u[k]
        if np.isfinite(lim[k, 0]):
            uk = ca.fmax(uk, float(lim[k, 0]))
        if np.isfinite(lim[k, 1]):
            uk = ca.fmin(uk, float(lim[k, 1]))
        out.append(uk)
    return ca.vertcat(*out)


def accommodation_gate(
    fhat: ca.SX, acc: dict, latch: ca.SX | None = None, memory: ca.SX | None = None, numbers=None, held=None
) -> ca.SX:
    """Per fault, 1 while its estimate is compensated in ``u``, else 0.

    Rule ``"explain"`` (what ``fte design`` writes for a plant whose faults' estimates cross-talk):
    :func:`_explained_gate`. Rule ``"isolate"`` (``fte simulate --accommodate``), with
    ``r_j = |fhat_j| / threshold_j``: fault j switches on when it is detected and isolated: ``r_j >= 1`` and ``r_j >= r_q`` for every other
    fault q (the largest normalised residual wins; a tie keeps both). Without ``latch`` (no ``"release"``
    in ``acc``, or 1) that is the gate, memoryless. With ``latch`` (the previous sample's gates, 0 or 1) and
    the release ratio ``rho = acc["release"]`` < 1, a fault that was on stays on while ``r_j >= rho``,
    unless another fault q switches on with ``r_q > r_j`` (isolation while latched: at most one fault is
    compensated, ties aside). With ``rho = 1`` this is the memoryless gate exactly: a latched fault with
    ``r_j >= 1`` and no larger ratio switches on anyway, and a larger ratio >= 1 means the largest one
    switches on. Either rule: a fault listed in ``acc["never"]`` is never compensated (``fte design`` lists a fault
    whose compensation measured worse than none in every one of its own windows:
    :func:`fte_casadi.sim._accommodate.protected`). ``numbers``: where the gate's numbers come from
    (:func:`step_function`); ``held``: per fault
    the largest ``|fhat_q|`` held so far, decaying (the memories after this sample's update), for rule
    ``"explain"`` with ``crosstalk_held``."""
    numbers = _Folded() if numbers is None else numbers
    thr = [numbers.scalar(f"threshold_{j}", v) for j, v in enumerate(acc["thresholds"])]
    if acc.get("rule") == "explain":
        gates = _explained_gate(fhat, acc, thr, latch, memory, numbers, held)
    else:
        gates = _isolating_gate(fhat, acc, thr, latch, numbers)
    never = set(
        acc.get("never") or ()
    )  # faults whose compensation measured worse than none in their own windows
    if never:
        gates = ca.vertcat(*[ca.SX(0.0) if j in never else gates[j] for j in range(len(thr))])
    return gates


def _isolating_gate(fhat: ca.SX, acc: dict, thr: list, latch: ca.SX | None, numbers) -> ca.SX:
    """The gate of rule ``"isolate"`` (:func:`accommodation_gate`)."""
    lf = len(thr)
    rr = [ca.fabs(fhat[j]) / thr[j] for j in range(lf)]
    on = []
    for j in range(lf):
        g = rr[j] >= 1.0
        for q in range(lf):
            if q != j:
                g = g * (rr[j] >= rr[q])
        on.append(g)
    if latch is None:
        return ca.vertcat(*on)
    rho = numbers.scalar("release", acc["release"])
    gates = []
    for j in range(lf):
        hold = (latch[j] > 0.5) * (rr[j] >= rho)
        for q in range(lf):
            if q != j:
                hold = hold * (1 - on[q] * (rr[q] > rr[j]))
        gates.append(ca.fmax(on[j], hold))
    return ca.vertcat(*gates)


def _explained_gate(
    fhat: ca.SX,
    acc: dict,
    thr: list,
    latch: ca.SX | None,
    memory: ca.SX | None = None,
    numbers=None,
    held=None,
) -> ca.SX:
    """The gate of rule ``"explain"`` (:mod:`fte_casadi.design._isolation`): fault j is compensated while
    ``r_j = |fhat_j| / (threshold_j + sum_q crosstalk[j][q] |fhat_q| + overshoot_j m_j) >= 1``, i.e. detected and
    larger than the other faults' estimates and its own fault's end can explain (``m_j``, with ``memory``: the
    held extreme of the other sign than ``fhat_j``'s; the estimate of a fault that has just ended swings past
    zero by up to ``overshoot_j`` of it); with a release ratio ``rho < 1`` and ``latch``, it stays on while
    ``r_j >= rho``. A fault that no other fault's estimate explains (its row of ``crosstalk`` zero: a plant with
    one fault) is compensated always, as in the paper: a gate would only delay it. With ``crosstalk_held`` in
    ``acc`` (and ``held``), each other fault's term is the smaller of ``crosstalk[j][q] |fhat_q|`` and
    ``crosstalk_held[j][q] M_q``, ``M_q`` its held estimate (:func:`fte_casadi.design._isolation.crosstalk_held`):
    both bound the cross-talk of a step of fault q, so their smaller does too."""
    ct = np.asarray(acc["crosstalk"], dtype=float)
    ch = acc.get("crosstalk_held") if held is not None else None
    ch = None if ch is None else np.asarray(ch, dtype=float)
    lf = len(thr)
    ov = acc.get("overshoot")
    gates = []
    for j in range(lf):
        sources = [q for q in range(lf) if q != j and ct[j, q] > 0]
        if not sources and not (memory is not None and ov[j] > 0):
            gates.append(ca.SX(1.0))
            continue
        b = thr[j]
        for q in sources:
            now = numbers.scalar(f"crosstalk_{j}_{q}", ct[j, q]) * ca.fabs(fhat[q])
            if ch is not None:
                now = ca.fmin(now, numbers.scalar(f"crosstalk_held_{j}_{q}", ch[j, q]) * held[q])
            b = b + now
        if memory is not None and ov[j] > 0:  # its own swing past the other sign's recent extreme
            other = ca.if_else(fhat[j] >= 0, memory[lf + j], memory[j])
            b = b + numbers.scalar(f"overshoot_{j}", ov[j]) * other
        r = ca.fabs(fhat[j]) / b
        on = r >= 1.0
        if latch is not None:
            on = ca.fmax(on, (latch[j] > 0.5) * (r >= numbers.scalar("release", acc["release"])))
        gates.append(on)
    return ca.vertcat(*gates)


def step_function(
    design: Design,
    sample_time: float,
    *,
    tolerant: bool = True,
    boundary_layer: float | None = None,
    name: str = "fte_step",
    numbers: StepParameters | None = None,
) -> ca.Function:
    """Build the step ``(z, y) -> (z_next, u, xbarhat, yc, s)`` of a design at ``sample_time``.

    ``z`` has ``design.nz`` values: the observer state (nbar), then, for an accommodation gate with a
    release ratio below 1 (``design.latched``), the gate's latches, one per fault (0 or 1; ``z_next`` holds
    the gates this sample applied), then, for a gate of rule ``"explain"`` with ``overshoot``
    (``design.remembers``), its memories: per fault the largest positive estimate, then per fault the largest
    negative one (as a magnitude), each the larger of the estimate now and the held one times
    ``exp(-Ts / memory_time)``.

    Parameters
    ----------
    design : Design
        The design record (gains, H, T, memberships).
    sample_time : float
        The observer/controller's sample time Ts; must be positive (the caller checks it against
        ``checks.ts_max``). The former keyword ``ts`` was removed in 0.2.0: giving it is a ``TypeError``.
    tolerant : bool
        With tolerant control (Kf term and sensor compensation) or without it.
    boundary_layer : float, optional
        Replace ``sgn(s)`` by ``sat(s / phi)``; ``None``: the design's ``params.boundary_layer``
        when it has one, else the discontinuous ``sgn`` with ``sgn(0) = 0``.
    numbers : StepParameters, optional
        Where the design's numbers come from: ``None`` folds them into the Function as constants (the C
        generator's step); a :class:`StepParameters` makes them symbols, which the Function then reads as free
        variables (the caller builds a Function with ``numbers.symbols`` as an input).
    """
    if not (isinstance(sample_time, (int, float)) and np.isfinite(sample_time) and sample_time > 0):
        raise ParameterError(f"sample time must be a positive number; got {sample_time!r}")
    if (
        boundary_layer is None
    ):  # a design chosen with one (fte tune) carries it: the simulation and the C follow
        boundary_layer = design.params.boundary_layer
    if boundary_layer is not None and not (np.isfinite(boundary_layer) and boundary_layer > 0):
        raise ParameterError(f"boundary layer must be a positive number; got {boundary_layer!r}")
    c = _Folded() if numbers is None else numbers
    dims = design.dims
    n, m, p, lf, r, nbar = (int(v) for v in (dims.n, dims.m, dims.p, dims.lf, dims.r, dims.nbar))
    latched = design.latched  # the gate's latches follow z in the step's state
    zz = ca.SX.sym("z", design.nz)
    nl = lf if latched else 0
    z, latch = zz[:nbar], (zz[nbar : nbar + nl] if latched else None)
    memory = zz[nbar + nl :] if design.remembers else None
    y = ca.SX.sym("y", p)

    xbh = z + ca.mtimes(c.matrix("H", design.H), y)
    xhat = xbh[:n]
    fhat = xbh[n + lf :]
    h = design.scheduling_function()(y, xhat)

    # C and Df are the plant's (their ones and zeros stay constants: 1 * x is x), not the design's numbers
    Cbar = np.hstack([design.C, np.zeros((p, lf)), design.Df])
    s = ca.mtimes(c.matrix("N", design.N), y - ca.mtimes(_dm(Cbar), xbh))
    g = design.sliding_gain()  # delta + eps per fault; with Remark 5 first one gain per undecoupled direction
    gain = c.scalar("sliding_gain", g[0]) if np.all(g == g[0]) else c.matrix("sliding_gains", g)
    if boundary_layer is None:
        us = gain * ca.sign(s)
    else:
        us = gain * ca.fmin(ca.fmax(s / c.scalar("boundary_layer", boundary_layer), -1.0), 1.0)

    u = c.matrix("u_ref", design.u_ref)
    for j in range(r):
        uj = ca.mtimes(c.matrix(f"K_{j}", design.K[j]), xhat)
        u = u + h[j] * uj
    hi = lo = held = None
    if memory is not None:  # each estimate's largest and smallest, decaying with memory_time
        k = c.scalar("memory_decay", np.exp(-float(sample_time) / float(design.accommodation["memory_time"])))
        hi = [ca.fmax(ca.fmax(fhat[j], 0.0), k * memory[j]) for j in range(lf)]
        lo = [ca.fmax(ca.fmax(-fhat[j], 0.0), k * memory[lf + j]) for j in range(lf)]
        held = [ca.fmax(a, b) for a, b in zip(hi, lo)]
    gate = (
        None
        if design.accommodation is None
        else accommodation_gate(fhat, design.accommodation, latch, memory, c, held)
    )
    fcomp = fhat if gate is None else fhat * gate
    if tolerant and design.Kf_rules is not None:  # Kf(h) = sum_i h_i Kf_i where the rules' Kf_i differ
        for i in range(r):
            u = u + h[i] * ca.mtimes(c.matrix(f"Kf_{i}", design.Kf_rules[i]), fcomp)
        yc = y - ca.mtimes(_dm(design.Df), fhat)
    elif tolerant:
        u = u + ca.mtimes(c.matrix("Kf", design.Kf), fcomp)
        yc = y - ca.mtimes(_dm(design.Df), fhat)
    else:
        yc = y
    u = saturate(u, design.input_limits)

    T = np.asarray(design.T)
    # Ls = T J1 (T [Bdbar_u J1]) for every rule, and sum_i h_i = 1
    rhs = ca.mtimes(c.matrix("Ls", design.Ls), us)
    for i in range(r):
        lm = design.local_models[i]
        Bbar = np.vstack([lm.B, np.zeros((2 * lf, m))])
        abar = np.concatenate([lm.a.ravel(), np.zeros(2 * lf)])
        TB = T @ Bbar
        Ly = np.asarray(design.L1[i]) + np.asarray(design.L2[i])
        Ta = T @ abar
        term = (
            ca.mtimes(c.matrix(f"R_{i}", design.R[i]), z)
            + ca.mtimes(c.matrix(f"TB_{i}", TB), u)
            + ca.mtimes(c.matrix(f"Ly_{i}", Ly), y)
        )
        if np.any(Ta):
            term = term + c.matrix(f"Ta_{i}", Ta)
        rhs = rhs + h[i] * term
    z_next = z + c.scalar("sample_time", sample_time) * rhs
    if latched:  # the gates of this sample are the next sample's latches
        z_next = ca.vertcat(z_next, gate)
    if memory is not None:
        z_next = ca.vertcat(z_next, *hi, *lo)
    # with symbols for the design's numbers, they are the Function's free variables: the caller's Function has them
    # as an input (numbers.symbols)
    opts = {} if numbers is None else {"allow_free": True}
    return ca.Function(name, [zz, y], [z_next, u, xbh, yc, s], list(STEP_INPUTS), list(STEP_OUTPUTS), opts)
