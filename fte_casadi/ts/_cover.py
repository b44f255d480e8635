"""Premises covered together: groups of premises that depend on shared states, and the polytope of
few vertices that encloses each group's image over the region.

The sector method blends local models at the vertices of a polytope that contains the premise
vector ``z(x)`` for every state of the region; the blended model equals the plant exactly when the
memberships reproduce ``z(x)`` (``sum_i h_i v_i = z``, ``h_i >= 0``, ``sum_i h_i = 1``), because the
coefficient matrices are affine in ``z``. One premise on ``[min, max]`` is the classical sector
(two vertices); ``p`` independent premises the box (``2^p`` vertices). Premises that depend on shared
states do not vary independently: their image is a curve or a low-dimensional surface, and a box
puts vertices where no state ever takes them (the entries of ``M(q)^-1`` of an arm at independent
extremes, which no configuration has). Here:

- premises are grouped by the states they depend on (those that depend on the same states form a
  group);
- a group of ``k`` premises whose image spans an affine space of dimension ``r`` is enclosed by a
  simplex of ``r + 1`` vertices: facet normals chosen to make it small around sampled points of the
  image (in coordinates whitened by the image's own spread), then each facet pushed out to the
  certified maximum of its linear form over the region (:func:`~fte_casadi.ts._premise_bounds.certified_max`:
  a dense grid, a Lipschitz bound per cell and a local search from every cell that could exceed
  the best value; not sampling alone). Its memberships are the barycentric coordinates, affine in
  ``z`` and in closed form: ``h = T^-1 [W (z - c); 1]``;
- the box of the group's premises (today's product of sector weights) is the alternative; each group
  takes the one with fewer vertices (a single premise: the sector, rule 1 at ``max``);
- where one group per set of states would give more than :data:`MERGE_ABOVE` rules, groups whose states are
  nested are covered together (:func:`_groups`): a quadrotor's premises of roll alone join those of roll
  and pitch, 48 rules instead of 108, each merged simplex looser around its image;
- an image of :data:`LARGE_IMAGE` dimensions or more gets its simplex's normals from a simplex inside the
  sampled image (successive projections) or a regular one turned at random, improved by a budgeted search
  (:func:`_large_simplex`), since the search from five starts over all normals takes minutes there.

Rules are the products of the groups' vertices, the first group varying slowest. Outside the
polytope (outside the region) the barycentric weights are clipped at 0 and renormalised, so they stay
a convex sum, as the sector weights saturate.

Not done: Baranyi's tensor-product (TP) transformation (HOSVD of the sampled model, then a convex
hull of its weighting functions), which can give fewer rules at a stated approximation error (exact, the
quadrotor's ranks 3 in roll, 5 in pitch, 3 in yaw and 2 in the yaw rate give 90 rules); and a descriptor form
keeping ``M(q)`` on the left.
"""

from __future__ import annotations

import functools
import itertools
import math
from dataclasses import dataclass

import casadi as ca
import numpy as np

from ._premise_bounds import certified_max, minimize

__all__ = ["GroupCover", "cover_premises", "VERTEX_CHOICES", "MERGE_ABOVE", "estimate_rules", "plan_groups"]

#: how the premises are covered: ``grouped`` (by the states they depend on, the fewer vertices per group),
#: ``box`` (each premise its own sector: 2^p rules, the most vertices), ``fewest`` (one simplex over
#: all premises: the fewest rules, the loosest)
VERTEX_CHOICES = ("grouped", "box", "fewest")
#: above this many rules the grouped cover covers groups of nested states together (:func:`_groups`)
MERGE_ABOVE = 64
#: random states of the region sampled for a group's image
_IMAGE_SAMPLES = 4000
#: an image of this many dimensions or more gets its simplex by :func:`_large_simplex` (seconds, not minutes)
LARGE_IMAGE = 4
#: random turns of a regular simplex tried, directions whose extreme points stand for the image, and the
#: evaluations per normal entry that :func:`_large_simplex` spends
LARGE_TURNS, LARGE_DIRECTIONS, LARGE_BUDGET = 32, 2000, 100
#: relative size below which a direction of the image's spread is taken as absent (an affine relation)
_RANK_TOL = 1e-9


@dataclass(frozen=True)
class GroupCover:
    """One group of premises and the polytope that covers its image over the region."""

    #: indices of the group's premises (in the model's premise order)
    premises: tuple[int, ...]
    #: states the group depends on
    states: tuple[int, ...]
    #: "box" (products of sector weights) or "simplex" (barycentric weights)
    polytope: str
    #: premise values of each vertex, (vertices, len(premises)), in the group's rule order
    vertices: np.ndarray
    #: affine dimension of the image (r) and the vertex counts of both covers
    dimension: int
    box_vertices: int
    simplex_vertices: int
    #: per vertex, the distance to the nearest sampled point of the image, relative to the image's
    #: extent (the largest distance between two of its points, premises scaled by their ranges)
    vertex_distance: tuple[float, ...]
    #: volume of the polytope over the volume of the image's convex hull (both in the image's affine
    #: span, premises scaled by their ranges); None where the hull could not be computed
    volume_ratio: float | None
    #: the same two numbers for the box of the group, for the comparison
    box_vertex_distance: float
    box_volume_ratio: float | None
    #: barycentric map of a simplex: h = Tinv @ [W (z - c); 1]
    _map: tuple | None = None

    def weights(self, z: ca.SX) -> list[ca.SX]:
        """Memberships of the group's vertices as CasADi expressions of its premise values ``z``."""
        if self.polytope == "box":
            mins, maxs = self.vertices.min(axis=0), self.vertices.max(axis=0)
            wmax, wmin = [], []
            for k in range(len(self.premises)):
                s = ca.fmin(ca.fmax(z[k], mins[k]), maxs[k])
                wmax.append((s - mins[k]) / (maxs[k] - mins[k]))
                wmin.append((maxs[k] - s) / (maxs[k] - mins[k]))
            out = []
            for bits in itertools.product((0, 1), repeat=len(self.premises)):
                term = ca.SX(1.0)
                for k, b in enumerate(bits):
                    term = term * (wmax[k] if b == 0 else wmin[k])
                out.append(term)
            return out
        Tinv, W, c = self._map
        y = ca.mtimes(ca.DM(W), z - ca.DM(c))
        h = ca.mtimes(ca.DM(Tinv), ca.vertcat(y, 1.0))
        hp = ca.fmax(h, 0.0)
        return [hp[i] / ca.sum1(hp) for i in range(hp.numel())]

    def inside(self, Z: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Per column of the group's premise values ``Z`` (k, N): inside the polytope (to ``tol``)?"""
        if self.polytope == "box":
            mn, mx = self.vertices.min(axis=0)[:, None], self.vertices.max(axis=0)[:, None]
            t = tol * np.maximum(np.abs(mn), np.abs(mx))  # relative: premises in any unit
            return np.all((Z >= mn - t) & (Z <= mx + t), axis=0)
        Tinv, W, c = self._map
        h = Tinv @ np.vstack([W @ (Z - c[:, None]), np.ones(Z.shape[1])])
        return np.all(h >= -tol, axis=0)

    def to_dict(self, names) -> dict:
        return {
            "premises": [names[k] for k in self.premises],
            "polytope": self.polytope,
            "vertices": len(self.vertices),
            "image_dimension": self.dimension,
            "box_vertices": self.box_vertices,
            "simplex_vertices": self.simplex_vertices,
            "max_vertex_distance": float(max(self.vertex_distance)),
            "volume_ratio": self.volume_ratio,
            "box_max_vertex_distance": float(self.box_vertex_distance),
            "box_volume_ratio": self.box_volume_ratio,
        }


def _vertex_estimate(k: int) -> int:
    """Vertices of the cover of a group of ``k`` premises, at most: the fewer of the simplex's ``k + 1`` (its
    image may span fewer dimensions) and the box's ``2^k``."""
    return min(2**k, k + 1)


def estimate_rules(groups: list[list[int]]) -> int:
    """Rules of the cover of these groups of premises, at most (:func:`_vertex_estimate` per group)."""
    return int(np.prod([_vertex_estimate(len(g)) for g in groups])) if groups else 1


def _groups(states: list[tuple[int, ...]], how: str, merge: bool = True) -> list[list[int]]:
    """Premise indices per group: the premises that depend on the same states (``grouped``), one each
    (``box``), all together (``fewest``); in the order of their first premise.

    ``grouped`` with more than :data:`MERGE_ABOVE` rules (:func:`estimate_rules`) then covers together
    groups whose states are nested, one pair at a time until there are no more than that: the group on the
    fewest states joins the group on the fewest states that contain its states (then the first by premise
    order). A quadrotor's premises of roll alone (cos(phi), sin(phi)) join those of roll and pitch: their
    rules multiply no more."""
    q = len(states)
    if how == "box":
        return [[k] for k in range(q)]
    if how == "fewest":
        return [list(range(q))] if q else []
    by_states: dict[tuple[int, ...], list[int]] = {}
    for k, st in enumerate(states):
        by_states.setdefault(tuple(sorted(st)), []).append(k)
    groups = sorted(by_states.values(), key=lambda g: g[0])
    sets = [set(states[g[0]]) for g in groups]
    while merge and estimate_rules(groups) > MERGE_ABOVE:
        pairs = [(len(sets[a]), groups[a][0], len(sets[b]), groups[b][0], a, b)
                 for a in range(len(groups)) for b in range(len(groups)) if a != b and sets[a] < sets[b]]  # fmt: skip
        if not pairs:
            break
        *_, a, b = min(pairs)
        groups[b] = sorted(groups[b] + groups[a])
        del groups[a], sets[a]
        order = sorted(range(len(groups)), key=lambda i: groups[i][0])
        groups, sets = [groups[i] for i in order], [sets[i] for i in order]
    return groups


def plan_groups(states: list[tuple[int, ...]], how: str = "grouped", merge: bool = True) -> list[list[int]]:
    """The groups :func:`cover_premises` makes of premises depending on ``states`` (per premise, the states);
    with ``merge=False`` those before groups of nested states are merged."""
    return _groups([tuple(st) for st in states], how, merge)


def _image(z_fn: ca.Function, states, lo, hi, n: int, rng) -> np.ndarray:
    """Premise values (k, N) at random states of the region and at the corners of the group's box."""
    N = _IMAGE_SAMPLES
    X = np.zeros((n, N))
    for j in states:
        X[j] = lo[j] + (hi[j] - lo[j]) * rng.random(N)
    corners = np.array(list(itertools.product((0, 1), repeat=len(states)))).T if len(states) <= 10 else None
    if corners is not None:
        Xc = np.zeros((n, corners.shape[1]))
        for r, j in enumerate(states):
            Xc[j] = np.where(corners[r] == 0, lo[j], hi[j])
        X = np.hstack([X, Xc])
    return np.array(z_fn.map(X.shape[1])(X)).reshape(-1, X.shape[1])


def _simplex_vertices(A: np.ndarray, b: np.ndarray) -> np.ndarray | None:
    """Vertices of ``{y : A y <= b}`` (r + 1 facets in r dimensions), vertex i opposite facet i; None when
    it is unbounded or degenerate."""
    m, r = A.shape
    lam = np.linalg.svd(A.T)[2][-1]  # lam^T A = 0
    if not (np.all(lam > 1e-9) or np.all(lam < -1e-9)):
        return None
    V = np.zeros((m, r))
    for i in range(m):
        rows = [k for k in range(m) if k != i]
        try:
            V[i] = np.linalg.solve(A[rows], b[rows])
        except np.linalg.LinAlgError:
            return None
    return V


def _facets_log_volume(A: np.ndarray, b: np.ndarray) -> float:
    """``log(r! vol)`` of the simplex ``{y : A y <= b}`` (r + 1 facets in r dimensions) from its facets alone:
    ``vol = |det [A b]|^r / (r! prod_i |det A_-i|)`` (A_-i: A without row i), the search's objective, with
    no vertex solved for. It is bounded when the cofactors ``(-1)^i det A_-i`` (the weights with
    ``lam^T A = 0``) share one sign; 1e6 where it is unbounded or degenerate (as :func:`_simplex_vertices`
    says None), inf where it has no volume."""
    m = A.shape[0]
    rows, alternate = _without_each_row(m)
    signs, logs = np.linalg.slogdet(A[rows])
    size = np.exp(logs - logs.max())  # |lam_i| / max |lam|
    if abs(float(np.sum(signs * alternate))) != m or size.min() <= 1e-9 * np.sqrt(size @ size):
        return 1e6
    sign, logdet = np.linalg.slogdet(np.hstack((A, b[:, None])))
    return (m - 1) * logdet - float(np.sum(logs)) if sign != 0 else np.inf


@functools.cache
def _without_each_row(m: int) -> tuple[np.ndarray, np.ndarray]:
    """The row indices of A_-i for i < m, and the cofactors' signs (-1)^i."""
    return np.array([[k for k in range(m) if k != i] for i in range(m)]), (-1.0) ** np.arange(m)


def _regular_normals(r: int) -> np.ndarray:
    """r + 1 unit vectors in r dimensions summing to zero (the facet normals of a regular simplex)."""
    E = np.eye(r + 1) - 1.0 / (r + 1)
    U = np.linalg.svd(E)[0][:, :r]  # orthonormal basis of the sum-zero plane
    N = E @ U
    return N / np.linalg.norm(N, axis=1, keepdims=True)


def _small_simplex(Y: np.ndarray, rng) -> np.ndarray:
    """Facet normals (r + 1, r) of a small simplex around the points ``Y`` (r, N), whitened."""
    r = Y.shape[0]
    if r == 1:
        return np.array([[1.0], [-1.0]])
    best = None
    base = _regular_normals(r)

    def objective(a):
        A = a.reshape(r + 1, r)
        A = A / np.linalg.norm(A, axis=1, keepdims=True)
        return _facets_log_volume(A, np.max(A @ Y, axis=1))

    if r >= LARGE_IMAGE:
        return _large_simplex(Y, rng)
    starts = [base] + [base @ np.linalg.qr(rng.normal(size=(r, r)))[0] for _ in range(4)]
    for A0 in starts:
        res = minimize(objective, A0.ravel(), method="Powell", options={"maxfev": 4000 * r, "xtol": 1e-4})
        if best is None or res.fun < best[0]:
            best = (res.fun, res.x)
    A = best[1].reshape(r + 1, r)
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _inscribed(Y: np.ndarray) -> list[int]:
    """Columns of ``Y`` (r, N) spanning a large simplex inside its points: the point farthest from their mean,
    then each time the point farthest from the affine span of those chosen (successive projections)."""
    r = Y.shape[0]
    idx = [int(np.argmax(np.sum((Y - Y.mean(axis=1, keepdims=True)) ** 2, axis=0)))]
    for _ in range(r):
        D = Y - Y[:, idx[:1]]
        if len(idx) > 1:
            Q = np.linalg.qr(Y[:, idx[1:]] - Y[:, idx[:1]])[0]
            D = D - Q @ (Q.T @ D)
        idx.append(int(np.argmax(np.sum(D**2, axis=0))))
    return idx


def _facet_normals(P: np.ndarray) -> np.ndarray | None:
    """Outward unit normals (r + 1, r) of the facets of the simplex with vertices the columns of ``P`` (r, r + 1),
    facet i opposite vertex i; None when the vertices are degenerate."""
    r = P.shape[0]
    try:  # barycentric coordinate i >= 0 is -A_i y <= ...
        A = -np.linalg.inv(np.vstack([P, np.ones(r + 1)]))[:, :r]
    except np.linalg.LinAlgError:
        return None
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _large_simplex(Y: np.ndarray, rng) -> np.ndarray:
    """Facet normals of a small simplex around ``Y`` (r, N) for an image of many dimensions, where a search over
    all ``r (r + 1)`` normals' entries from several starts (:func:`_small_simplex`) takes minutes: the facets of
    a large simplex inside the points (:func:`_inscribed`) pushed out to them, or of a regular simplex turned at
    random, whichever is the smallest, then improved by the same search, from that start only, on the points
    that are extreme in some direction (a few hundred) and with a budget of evaluations."""
    r = Y.shape[0]
    base = _regular_normals(r)
    starts = [base @ np.linalg.qr(rng.normal(size=(r, r)))[0] for _ in range(LARGE_TURNS)]
    inner = _facet_normals(Y[:, _inscribed(Y)])
    starts = ([inner] if inner is not None else []) + [base] + starts
    ext = Y[:, np.unique(np.argmax(rng.normal(size=(LARGE_DIRECTIONS, r)) @ Y, axis=1))]

    def objective(a):
        A = a.reshape(r + 1, r)
        A = A / np.linalg.norm(A, axis=1, keepdims=True)
        return _facets_log_volume(A, np.max(A @ ext, axis=1))

    A0 = min(starts, key=lambda A: objective(A.ravel()))
    res = minimize(objective, A0.ravel(), method="Powell",
                   options={"maxfev": LARGE_BUDGET * r * (r + 1), "xtol": 1e-4})  # fmt: skip
    A = (res.x if res.fun < objective(A0.ravel()) else A0.ravel()).reshape(r + 1, r)
    return A / np.linalg.norm(A, axis=1, keepdims=True)


def _distances(V: np.ndarray, P: np.ndarray) -> np.ndarray:
    """Per vertex (rows of V), the distance to the nearest column of P."""
    return np.array([float(np.min(np.linalg.norm(P - v[:, None], axis=0))) for v in V])


def _hull_volume(P: np.ndarray) -> float | None:
    """Volume of the convex hull of the columns of P (r, N), r <= 6; None otherwise or on failure."""
    r = P.shape[0]
    if r == 1:
        return float(np.ptp(P))
    if r > 6:
        return None
    try:
        from scipy.spatial import ConvexHull

        return float(ConvexHull(P.T).volume)
    except Exception:  # noqa: BLE001 -- a degenerate or too large hull: no ratio reported
        return None


def _simplex_volume(V: np.ndarray) -> float:
    r = V.shape[1]
    return float(abs(np.linalg.det(V[1:] - V[0])) / math.factorial(r)) if r > 1 else float(np.ptp(V))


def cover_premises(z_exprs: ca.SX, x: ca.SX, lo, hi, mins, maxs, states, how: str = "grouped", seed: int = 0):
    """The groups of the premises ``z_exprs(x)`` and the polytope covering each (see the module docstring).

    ``mins``/``maxs``: the premises' certified bounds (the box cover); ``states``: per premise, the states
    it depends on. Returns a tuple of :class:`GroupCover`.
    """
    q = z_exprs.numel()
    if q == 0:
        return ()
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    mins, maxs = np.asarray(mins, float), np.asarray(maxs, float)
    rng = np.random.default_rng(seed)
    n = x.numel()
    out = []
    for g in _groups([tuple(s) for s in states], how):
        k = len(g)
        st = tuple(sorted({j for i in g for j in states[i]}))
        ze = ca.vertcat(*[z_exprs[i] for i in g])
        Z = _image(ca.Function("zg", [x], [ze]), st, lo, hi, n, rng)  # (k, N)
        scale = np.where(maxs[g] > mins[g], maxs[g] - mins[g], 1.0)
        Zs = Z / scale[:, None]  # premises scaled by their ranges
        c = Zs.mean(axis=1)
        U, S, _ = np.linalg.svd(Zs - c[:, None], full_matrices=False)
        r = int(np.sum(S > _RANK_TOL * max(S[0], 1e-300))) if k else 0
        box = np.array(list(itertools.product(*[(maxs[i], mins[i]) for i in g])))  # rule order: max then min
        extent = float(np.max(np.linalg.norm(Zs - c[:, None], axis=0))) * 2 or 1.0
        Ur = U[:, :r]
        Y = Ur.T @ (Zs - c[:, None])
        hull = _hull_volume(Y)
        box_dist = float(np.max(_distances(box / scale, Zs))) / extent
        box_vol = float(np.prod(maxs[g] - mins[g]) / np.prod(scale)) if r == k else None
        box_ratio = (box_vol / hull) if (box_vol is not None and hull) else None
        simplex_count = r + 1
        use_simplex = how != "box" and simplex_count < 2**k
        if not use_simplex:
            out.append(GroupCover(tuple(g), st, "box", box, r, 2**k, simplex_count,
                                  tuple(float(v) for v in _distances(box / scale, Zs) / extent), box_ratio,
                                  box_dist, box_ratio))  # fmt: skip
            continue
        whiten = S[:r] / np.sqrt(Z.shape[1])
        Yw = Y / whiten[:, None]
        Aw = _small_simplex(Yw, rng)
        A = Aw / whiten[None, :]  # the same facets in the coordinates Y
        A = A / np.linalg.norm(A, axis=1, keepdims=True)
        # grow each facet to the certified maximum of its linear form a^T Ur^T (z / scale - c) over the region
        W = Ur.T / scale[None, :]  # y = W z - Ur^T c
        b = np.zeros(r + 1)
        for i in range(r + 1):
            form = ca.mtimes(ca.DM(A[i] @ W).T, ze) - float(A[i] @ Ur.T @ c)
            b[i] = max(certified_max(form, x, lo, hi), float(np.max(A[i] @ Y)))
            b[i] += 1e-12 * (1.0 + abs(b[i]))
        Vy = _simplex_vertices(A, b)
        Vz = (c[None, :] + Vy @ Ur.T) * scale[None, :]  # vertices in premise values
        T = np.vstack([Vy.T, np.ones(r + 1)])
        Tinv = np.linalg.inv(T)
        dist = _distances(Vy, Y) / extent
        vol = _simplex_volume(Vy) if r > 1 else float(np.ptp(Vy))
        out.append(GroupCover(tuple(g), st, "simplex", Vz, r, 2**k, simplex_count, tuple(float(v) for v in dist),
                              (vol / hull) if hull else None, box_dist, box_ratio,
                              (Tinv, W, _centre(Ur, c, scale))))  # fmt: skip
    return tuple(out)


def _centre(Ur, c, scale):
    """The point z_c with W (z - z_c) = Ur^T (z / scale - c): z_c = scale * (Ur Ur^T c)."""
    return scale * (Ur @ (Ur.T @ c))


def rule_vertices_of(groups, q: int) -> np.ndarray:
    """Premise values of each rule: products of the groups' vertices, the first group varying slowest."""
    if not groups:
        return np.zeros((1, q))
    rows = []
    for combo in itertools.product(*[range(len(g.vertices)) for g in groups]):
        z = np.zeros(q)
        for g, i in zip(groups, combo):
            z[list(g.premises)] = g.vertices[i]
        rows.append(z)
    return np.array(rows)


def memberships_of(groups, q: int) -> ca.Function:
    """``premise values (q) -> h``: products of the groups' memberships, in the order of
    :func:`rule_vertices_of`."""
    z = ca.SX.sym("z", q)
    per = [g.weights(ca.vertcat(*[z[i] for i in g.premises])) for g in groups]
    h = []
    for combo in itertools.product(*per):  # no group: one empty product, the single rule's weight 1
        term = ca.SX(1.0)
        for w in combo:
            term = term * w
        h.append(term)
    return ca.Function("memberships", [z], [ca.vertcat(*h)], ["premises"], ["h"])


def group_notes(premises, groups) -> tuple[str, ...]:
    """One line per group for reports: its premises, the polytope chosen, the trade-off."""
    if not groups:
        return ()
    names = [p.name for p in premises]
    total = int(np.prod([len(g.vertices) for g in groups]))
    out = [f"premises covered in {len(groups)} group{'s' * (len(groups) > 1)} by the states they depend on: "
           f"{total} rules (one box per premise: {2 ** len(premises)})"]  # fmt: skip
    for g in groups:
        ps = ", ".join(names[k] for k in g.premises)
        vr = "n/a" if g.volume_ratio is None else f"{g.volume_ratio:.3g}"
        bvr = "n/a" if g.box_volume_ratio is None else f"{g.box_volume_ratio:.3g}"
        out.append(
            f"group ({ps}) on {len(g.states)} state(s), image of dimension {g.dimension}: {g.polytope} of "
            f"{len(g.vertices)} vertices (simplex {g.simplex_vertices}, box {g.box_vertices}); farthest vertex "
            f"{max(g.vertex_distance):.3g} of the image's extent from it, volume {vr} x the image's hull "
            f"(box: {g.box_vertex_distance:.3g}, {bvr} x)"
        )
    return tuple(out)


def rule_distances(groups) -> np.ndarray:
    """Per rule, the largest distance from its vertices to the image (relative to the image's extent):
    near 0, a state of the region takes (nearly) that rule's premise values."""
    if not groups:
        return np.zeros(1)
    return np.array(
        [
            max(g.vertex_distance[i] for g, i in zip(groups, combo))
            for combo in itertools.product(*[range(len(g.vertices)) for g in groups])
        ]  # fmt: skip
    )
