"""What limits every design of a plant: the structure behind a fault estimate no tuning makes good.

When no certified design makes tolerant control better than none in a fault's window, or keeps
a fault's estimate quiet outside its windows, the cause is often in the plant, not in the knobs.
This module computes, from the local models and a design, the numbers that name such a cause:

- the invariant (transmission) zeros of the fault's channel to the outputs, per rule: the s where
  ``[[sI - A_i, Bf_ij], [C, Df_j]]`` loses rank, and the same with the unknown inputs beside the
  fault (``[Bf_ij, Bd_i]``, ``[Df_j, 0]``), which the observer must decouple. A zero in or near the
  right half plane limits how fast the fault can be recovered from the outputs;
- the slowest observer mode (the largest real part of the eigenvalues of R_i) against the length of
  the fault's window: an estimate still settling when the window is over is worse than none;
- how well the outputs separate the fault from the unknown inputs and from the other faults: the
  smallest singular value of the rank test of assumption (2) restricted to those columns
  (``[[A_i, Bf_S, Bd_S], [C, Df_S, 0]]``, columns scaled to unit length so that units do not
  matter). Near zero means the outputs tell them apart only slowly or under noise.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg as sla

from ..verdicts import FALSE_ALARM, SATURATED, SATURATES_EARLY, WORSE_THAN_NONE

__all__ = ["separation", "explain_metrics"]  # public: docs/api.md

#: a normalised separation below this is "weak" (the outputs tell the columns apart only slowly)
WEAK_SEPARATION = 5e-2
#: a zero beyond this many times the largest norm of (A, B, C, D) is an infinite one in round-off
FINITE_ZERO = 1e8
#: the settling time of a mode is taken as SETTLE_TAUS time constants
SETTLE_TAUS = 3.0
#: the part of a window the fault error leaves out for settling (metrics' SETTLE_FRACTION)
WINDOW_SETTLE = 0.2


def _rank(M: np.ndarray) -> int:
    """The numerical rank of M after equilibrating its rows, then its columns (diagonal scalings keep the
    rank; a fast plant's pencil has rows of 1e6 beside rows of 1e4, which a plain relative test misreads)."""
    M = np.asarray(M, dtype=complex)
    for axis in (1, 0):
        norms = np.linalg.norm(M, axis=axis, keepdims=True)
        M = M / np.where(norms > 0, norms, 1.0)
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > 1e-9 * max(1.0, s[0] if len(s) else 0.0)))


def channel_zeros(A, B, C, D, seed: int = 0) -> np.ndarray | None:
    """Finite invariant zeros of ``(A, B, C, D)``: the s where ``[[sI - A, B], [C, D]]`` loses rank.

    ``None`` when the pencil loses rank for every s (normal rank below ``n + columns of B``). A tall
    system (more outputs than inputs) is squared by a random orthonormal projection of its outputs
    (seeded), and each candidate is kept only when the full, unprojected pencil loses rank there.

    Examples
    --------
    >>> A = np.array([[0.0, 1.0], [-2.0, -3.0]]); B = np.array([[0.0], [1.0]])
    >>> C = np.array([[1.0, 1.0]]); D = np.zeros((1, 1))
    >>> np.round(channel_zeros(A, B, C, D).real, 6).tolist()
    [-1.0]
    """
    A, B, C, D = (np.atleast_2d(np.asarray(M, dtype=float)) for M in (A, B, C, D))
    n, k, p = A.shape[0], B.shape[1], C.shape[0]
    rng = np.random.default_rng(seed)
    scale = max(1.0, *(np.linalg.norm(M, 2) for M in (A, B, C, D)))
    s0 = complex(rng.normal(), rng.normal()) * np.linalg.norm(A, 2)  # at the plant's rates: a fast plant's
    if _rank(np.block([[s0 * np.eye(n) - A, B], [C, D]])) < n + k:  # pencil at s ~ 1 is near rank-deficient
        return None
    R = np.eye(p) if p == k else np.linalg.qr(rng.normal(size=(p, k)))[0].T
    Mp = np.block([[A, -B], [-(R @ C), -(R @ D)]])
    Ep = np.block([[np.eye(n), np.zeros((n, k))], [np.zeros((k, n + k))]])
    w = sla.eig(Mp, Ep, right=False)
    out = []
    # a finite eigenvalue far beyond every rate of the data is an infinite one in round-off (a PMSM's
    # 1e3/s currents gave 7.95e23): kept only within FINITE_ZERO times the data's largest norm
    w = w[np.isfinite(w)]
    for s in w[np.abs(w) <= FINITE_ZERO * scale]:
        Ms = np.block([[s * np.eye(n) - A, B], [C, D]])
        if np.linalg.svd(Ms, compute_uv=False)[-1] <= 1e-7 * scale * max(1.0, abs(s)):
            out.append(s)
    return np.array(out, dtype=complex)


def separation(A, B, C, D) -> float:
    """Smallest singular value of ``[[A, B], [C, D]]`` with every column scaled to unit length
    (0: the columns of B are not told apart from the outputs at all; assumption (2)'s test)."""
    M = np.block([[np.atleast_2d(A), np.atleast_2d(B)], [np.atleast_2d(C), np.atleast_2d(D)]])
    norms = np.linalg.norm(M, axis=0)
    M = M / np.where(norms > 0, norms, 1.0)
    return float(np.linalg.svd(M, compute_uv=False)[-1])


@dataclass(frozen=True)
class FaultLimits:
    """The structural numbers of one fault (see the module docstring)."""

    fault: str
    #: per rule, the invariant zero of the fault's channel (with the unknown inputs) with the largest
    #: real part; None where there is none (nan where the pencil loses rank for every s)
    rightmost_zero: tuple
    #: per rule: normalised smallest singular value of [[A_i, Bf_j, Bd_i], [C, Df_j, 0]]
    separation_inputs: tuple
    #: per rule: the same with the other faults beside it (fault j against faults k != j)
    separation_faults: tuple
    #: the largest real part of the eigenvalues of R_i over the rules (the slowest observer mode)
    slowest_mode: float
    #: whether the plant has unknown inputs (without, ``separation_inputs`` measures how well the outputs see the
    #: fault at all: the rank test of [[A_i, Bf_j], [C, Df_j]])
    has_unknown_inputs: bool = True

    @property
    def time_constant(self) -> float:
        return float("inf") if self.slowest_mode >= 0 else -1.0 / self.slowest_mode


def fault_limits(design, j: int) -> FaultLimits:
    """The numbers of fault ``j`` (in the plant's order) from ``design``'s local models and its R_i."""
    C, Df = np.asarray(design.C, float), np.asarray(design.Df, float)
    names = list(design.names.get("faults") or [f"f{k + 1}" for k in range(Df.shape[1])])
    zeros, sep_d, sep_f = [], [], []
    for lm in design.local_models:
        A, Bf, Bd = lm.A, lm.Bf, lm.Bd
        ld = Bd.shape[1]
        B = np.hstack([Bf[:, [j]], Bd])
        D = np.hstack([Df[:, [j]], np.zeros((C.shape[0], ld))])
        z = channel_zeros(A, B, C, D)
        zeros.append(
            float("nan") if z is None else (None if len(z) == 0 else complex(max(z, key=lambda v: v.real)))
        )
        sep_d.append(separation(A, B, C, D))
        sep_f.append(separation(A, Bf, C, Df) if Bf.shape[1] > 1 else float("inf"))
    slow = max(float(np.max(np.linalg.eigvals(np.asarray(R, float)).real)) for R in design.R)
    return FaultLimits(names[j], tuple(zeros), tuple(sep_d), tuple(sep_f), slow, ld > 0)


def _zero_text(z) -> str:
    if z is None:
        return "none"
    if isinstance(z, float):
        return "rank lost for every s"
    return f"{z.real:.3g}" + (f" {'+-'} {abs(z.imag):.3g}j" if abs(z.imag) > 1e-9 * max(1.0, abs(z)) else "")


def causes(lim: FaultLimits, window: float | None) -> tuple[list[str], str]:
    """The structural causes found for ``lim`` (sentences with numbers) and the numbers looked at."""
    found = []
    rule_z = [(i, z) for i, z in enumerate(lim.rightmost_zero) if isinstance(z, complex)]
    if any(isinstance(z, float) for z in lim.rightmost_zero):
        rules = [i + 1 for i, z in enumerate(lim.rightmost_zero) if isinstance(z, float)]
        found.append(f"the channel of {lim.fault} and the unknown inputs to the outputs loses rank for every s "
                     f"(rules {rules}): the outputs cannot recover {lim.fault} apart from them")  # fmt: skip
    if rule_z:
        i, z = max(rule_z, key=lambda t: t[1].real)
        near = 1.0 / window if window else 0.0
        if z.real >= 0:
            found.append(f"its channel to the outputs (with the unknown inputs) has an invariant zero at s = "
                         f"{_zero_text(z)} (rule {i + 1}) in the right half plane: the outputs respond to "
                         f"{lim.fault} first the wrong way, and no observer gain removes it")  # fmt: skip
        elif -z.real < near:
            found.append(f"its channel to the outputs has an invariant zero at s = {_zero_text(z)} (rule {i + 1}), "
                         f"slower than the window (1 / {window:g} = {near:.3g}): the outputs show {lim.fault} only "
                         "after the window is mostly over")  # fmt: skip
    tau = lim.time_constant
    if window and SETTLE_TAUS * tau > WINDOW_SETTLE * window:
        found.append(f"the slowest observer mode decays at rate {-lim.slowest_mode:.3g} (time constant {tau:.3g}): "
                     f"{SETTLE_TAUS:g} time constants = {SETTLE_TAUS * tau:.3g} against the {WINDOW_SETTLE:.0%} of the "
                     f"{window:g}-long window left for settling ({WINDOW_SETTLE * window:.3g})")  # fmt: skip
    k = int(np.argmin(lim.separation_inputs))
    if lim.separation_inputs[k] < WEAK_SEPARATION and lim.has_unknown_inputs:
        found.append(f"the outputs separate {lim.fault} from the unknown inputs only weakly: smallest singular "
                     f"value of the column-normalised rank test [[A_i, Bf, Bd], [C, Df, 0]] is "
                     f"{lim.separation_inputs[k]:.2g} (rule {k + 1})")  # fmt: skip
    elif lim.separation_inputs[k] < WEAK_SEPARATION:
        found.append(f"the outputs see {lim.fault} only weakly (the plant has no unknown inputs): smallest singular "
                     f"value of the column-normalised rank test [[A_i, Bf], [C, Df]] of {lim.fault} alone is "
                     f"{lim.separation_inputs[k]:.2g} (rule {k + 1})")  # fmt: skip
    kf = int(np.argmin(lim.separation_faults))
    if np.isfinite(lim.separation_faults[kf]) and lim.separation_faults[kf] < WEAK_SEPARATION:
        found.append(f"the outputs separate the faults from one another only weakly: smallest singular value of "
                     f"the column-normalised [[A_i, Bf], [C, Df]] is {lim.separation_faults[kf]:.2g} "
                     f"(rule {kf + 1})")  # fmt: skip
    zs = ", ".join(_zero_text(z) for z in lim.rightmost_zero)
    seen = (f"rightmost invariant zero per rule: {zs}; slowest observer mode {lim.slowest_mode:.3g} (time "
            f"constant {tau:.3g}); "
            + ("separation from the unknown inputs" if lim.has_unknown_inputs else "the fault's own rank test")
            + f" {min(lim.separation_inputs):.2g}"
            + (f", from the other faults {min(lim.separation_faults):.2g}"
               if np.isfinite(min(lim.separation_faults)) else ""))  # fmt: skip
    return found, seen


#: a loop whose gain moves the state this much less than the plant's own rates does not act (relative)
IDLE_GAIN = 1e-6


#: an FTC ratio this close to 1 is a tie (a window where tolerant control adds nothing to the loop)
TIE = 0.02


def fed_faults(design) -> list[int]:
    """The faults whose estimates tolerant control feeds into u: a nonzero column of Kf (of some rule's Kf_i)."""
    kfs = [design.Kf] if design.Kf_rules is None else list(design.Kf_rules)
    return [j for j in range(int(design.dims.lf)) if any(np.any(np.asarray(k)[:, j]) for k in kfs)]


def gated_out(design, j: int) -> str:
    """Why tolerant control adds nothing in a window of fault ``j``: its own estimate does not enter u (a zero
    column of Kf: a sensor fault, which the observer already removes from xhat for both runs) and the gate of
    rule "explain" keeps the other faults' estimates out (:mod:`fte_casadi.design._isolation`); or it is one the
    design never compensates (``accommodation["never"]``). "" otherwise."""
    acc = design.accommodation
    if acc is None or acc.get("rule") != "explain":
        return ""
    names = list(design.names.get("faults") or [])
    name = names[j] if j < len(names) else f"fault {j + 1}"
    if j in (acc.get("never") or ()):
        return (f"{name} is never compensated (the design measured its compensation worse than none in its own "
                "windows: accommodation.never), and the gate keeps the other faults' estimates out of u while they are "
                "no more than its cross-talk explains, so tolerant control adds nothing here: a ratio of 1 is a tie")  # fmt: skip
    if j in fed_faults(design):
        return ""
    return (f"{name}'s estimate does not enter u (its column of Kf is zero: the observer already removes it from xhat, "
            "which the loop without tolerant control uses too), and the gate keeps the other faults' estimates out of "
            "u while they are no more than its cross-talk explains, so tolerant control adds nothing here: a ratio of "
            "1 is a tie")  # fmt: skip


def loop_idle(design) -> str:
    """Why tolerant control changes nothing: the controller's gain is zero in effect (``max ||B_i K_j||``
    below :data:`IDLE_GAIN` times ``max ||A_i||``: a stable open loop, where step 3's smallest ``||Y'||`` asks
    no feedback). The estimates of sensor faults then reach the plant through no term, and an FTC ratio of 1
    is a tie. "" when the loop acts."""
    K = [np.asarray(k, float) for k in design.K]
    bk = max(float(np.linalg.norm(lm.B @ k, 2)) for lm in design.local_models for k in K)
    a = max(float(np.linalg.norm(lm.A, 2)) for lm in design.local_models)
    if bk > IDLE_GAIN * max(a, 1e-300):
        return ""
    return (f"the controller does not act: max ||B_i K_j|| = {bk:.2g} against the plant's rates max ||A_i|| = {a:.3g} "
            "(the open loop is stable and step 3 asks the smallest gain), so a fault estimate reaches the plant "
            "only through Kf fhat (none for a sensor fault) and tolerant control changes nothing: a ratio of 1 "
            "is a tie")  # fmt: skip


#: the measurement noise's input, as a standard deviation, that explains a saturated input: a third of its half-range
#: (three standard deviations reach the limit)
NOISE_SATURATES = 1.0 / 3.0


def noise_saturates(design, metrics: dict, w: dict) -> str:
    """Why an input is at its limits in window ``w``: the measurement noise alone moves it that far through the
    loop's direct path ``K_j H`` (``u = K_j xhat`` with ``xhat = z + H y``: a lower bound, the observer's dynamics
    add to it). "" where the noise does not explain it (or the run has no noise or the plant no limits)."""
    sat, noise, lims = w.get("input_saturation") or [], metrics.get("measurement_noise"), design.input_limits
    p, n = int(design.dims.p), int(design.dims.n)
    if lims is None or not isinstance(noise, (list, tuple)) or len(noise) != p:
        return ""
    V = np.diag(np.square(np.asarray(noise, dtype=float)))
    Hx = np.asarray(design.H, float)[:n]
    sd = np.max(
        [np.sqrt(np.diag(k @ Hx @ V @ Hx.T @ k.T)) for k in (np.asarray(k, float) for k in design.K)], axis=0
    )
    half = 0.5 * (np.asarray(lims, float)[:, 1] - np.asarray(lims, float)[:, 0])
    names = list(design.names.get("inputs") or [])
    p_ = design.params
    out = [f"input {names[i] if i < len(names) else i} is at a limit {100 * f:.0f} % of the window: the measurement "
           f"noise alone moves it by {sd[i]:.3g} (standard deviation through the loop's direct path K H, a lower bound) "
           f"against its half-range {half[i]:.3g}; max |K| = {max(float(np.abs(k).max()) for k in design.K):.3g} is step "
           f"3's smallest gain at sigma = {p_.sigma:g}, gamma = {p_.gamma:g} (and the loop's decay rate); it is no "
           "larger at a smaller sigma or a larger gamma, where (45) only admits more (fte tune searches them)"
           for i, f in enumerate(sat) if i < len(half) and f > SATURATED and sd[i] >= NOISE_SATURATES * half[i]]  # fmt: skip
    return "; ".join(out)


def saturates_early(design, w: dict) -> str:
    """Why an input is at its limits in window ``w``: the design's loop keeps its inputs within their limits only
    on a set far smaller than the plant's region (``checks.loop.unsaturated``, :data:`SATURATES_EARLY`). "" where
    no input saturates there, the design has no such record or the set is not that small."""
    room = ((design.checks or {}).get("loop") or {}).get("unsaturated") or {}
    frac, sat = room.get("fraction"), w.get("input_saturation") or []
    if frac is None or frac >= SATURATES_EARLY or not any(f > SATURATED for f in sat):
        return ""
    k = int(np.argmin([v / h if h else np.inf for v, h in zip(room["extent"], room["region_half_width"])]))
    names = list(design.names.get("states") or [])
    return (f"the design's loop keeps its inputs within their limits only while its Lyapunov function stays below "
            f"a level reaching {frac:.2g} of the plant's region ({names[k] if k < len(names) else k} "
            f"{room['extent'][k]:.3g} of {room['region_half_width'][k]:.3g}; fte design's 'input limits'): its gain "
            "saturates the input for deviations that small, and the certificate does not cover the loop that runs")  # fmt: skip


def explain_metrics(design, metrics: dict, *, windows=None, faults=None) -> list[str]:
    """One sentence per fault window where tolerant control is not better than none (FTC ratio >=
    :data:`~fte_casadi.verdicts.WORSE_THAN_NONE`) and per fault whose false-alarm ratio is >=
    :data:`~fte_casadi.verdicts.FALSE_ALARM` in ``metrics``, naming the structural cause with
    numbers, or saying that none was found (then the limit is the tuning or the noise, not the plant).

    ``windows``: indices of ``metrics["windows"]`` to explain (default: those with a ratio >= 1);
    ``faults``: indices of faults to explain for false alarms (default: those >= 1)."""
    names = list(design.names.get("faults") or [])
    out = []
    wins = metrics.get("windows") or []
    if windows is None:
        windows = [k for k, w in enumerate(wins) if (w.get("ftc_true_ratio") or 0.0) >= WORSE_THAN_NONE]
    for k in windows:
        w = wins[k]
        j = names.index(w["fault"]) if w["fault"] in names else 0
        lim = fault_limits(design, j)
        found, seen = causes(lim, float(w["stop"]) - float(w["start"]))
        r = w.get("ftc_true_ratio")
        tie = r is not None and abs(r - 1.0) <= TIE
        if tie and (idle := loop_idle(design)):
            found.insert(0, idle)
        if tie and (kept := gated_out(design, j)):
            found.insert(0, kept)
        if noisy := noise_saturates(design, metrics, w):
            found.insert(0, noisy)
        if early := saturates_early(design, w):
            found.insert(0, early)
        head = (f"in the window of {w['fault']} [{w['start']:g}, {w['stop']:g}) (FTC ratio "
                f"{'n/a' if r is None else format(r, '.3g')})")  # fmt: skip
        out.append(head + (": " + "; ".join(found) if found else ": no structural cause found")
                   + f" ({seen})")  # fmt: skip
    fa = metrics.get("false_alarm_peak") or []
    if faults is None:
        faults = [j for j, v in enumerate(fa) if v is not None and v >= FALSE_ALARM]
    for j in faults:
        lim = fault_limits(design, j)
        spans = [float(w["stop"]) - float(w["start"]) for w in wins if w["fault"] == lim.fault]
        found, seen = causes(lim, min(spans) if spans else None)
        v = fa[j] if j < len(fa) else None
        out.append(f"false alarms of {lim.fault} (ratio {'n/a' if v is None else format(v, '.3g')})"
                   + (": " + "; ".join(found) if found else ": no structural cause found") + f" ({seen})")  # fmt: skip
    return out


def vertex_reach(distances, i: int) -> str:
    """Whether a state of the region reaches rule ``i``'s vertex: its distance to the premises' image
    relative to the image's extent (``TSModel.rule_distances``); "" when not known."""
    if distances is None or i >= len(distances):
        return ""
    v = float(distances[i])
    if v <= NEAR_IMAGE:
        return f"rule {i + 1}'s vertex is one a state of the region reaches (distance {v:.2g} of the image's extent)"
    return (f"rule {i + 1}'s vertex is {v:.2g} of the image's extent away from every premise value a state of the "
            "region takes: no real state reaches it, it is there to enclose the image")  # fmt: skip


#: a vertex this close to the premises' image (relative to its extent) is taken as reached by a state
NEAR_IMAGE = 0.05


def reachability(aug, distances=None) -> str:
    """Why (45) may allow no sigma > 0 at all: per rule, the open-loop unstable modes of ``A_i`` and how
    well the inputs reach them (the smallest singular value of the PBH test ``[A_i - lambda I, B_i]``,
    relative to ``||[A_i, B_i]||``). A mode the inputs barely reach leaves (45) a margin sigma too small
    for any solver (e.g. an unstable mode at the far end of a chain driven at its head). "" when every
    rule is open-loop stable."""
    n = aug.n
    worst = None
    for i in range(aug.r):
        A, B = aug.Abar[i][:n, :n], aug.Bbar[i][:n]
        scale = max(float(np.linalg.norm(np.hstack([A, B]), 2)), 1e-300)
        for lam in np.linalg.eigvals(A):
            if lam.real <= 0:
                continue
            pbh = float(np.linalg.svd(np.hstack([A - lam * np.eye(n), B]), compute_uv=False)[-1]) / scale
            if worst is None or pbh < worst[2]:
                worst = (i, lam, pbh, sum(ev.real > 0 for ev in np.linalg.eigvals(A)))
    if worst is None:
        return ""
    i, lam, pbh, count = worst
    reach = vertex_reach(distances, i)
    return (f"the open loop is unstable ({count} mode(s) of rule {i + 1} in the right half plane, the least reachable at "
            f"{lam.real:.3g}{lam.imag:+.3g}j), and the inputs reach it only as much as the relative PBH test "
            f"sigma_min([A - lambda I, B]) / ||[A, B]|| = {pbh:.2g} says: a controller must stabilise it through that, "
            "which leaves (45) little or no margin sigma" + (f"; {reach}" if reach else ""))  # fmt: skip
