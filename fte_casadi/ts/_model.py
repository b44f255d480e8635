"""The T-S fuzzy model record: premises, local models, memberships, fidelity."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Literal

import casadi as ca
import numpy as np

from ..model import Plant

__all__ = ["Premise", "LocalModel", "LOCAL_MODEL_KEYS", "Fidelity", "TSModel", "Kind", "METHOD_TEXT"]

#: how a T-S model was derived: the sector method on premises the plant declares (``"sector"``) or
#: that the toolkit found (``"sector_auto"``), one rule for a plant without nonlinear term
#: (``"linear"``), or local linearisation at operating points (``"linearisation"``)
Kind = Literal["sector", "sector_auto", "linear", "linearisation"]
#: the text that reports and the derive document show for each kind (:attr:`TSModel.method`)
METHOD_TEXT: dict[str, str] = {
    "sector": "sector",
    "sector_auto": "sector (premises found automatically)",
    "linear": "linear (one rule)",
    "linearisation": "linearisation",
}


@dataclass(frozen=True)
class Premise:
    """A premise (scheduling) variable and its bounds over the plant's region."""

    name: str
    expr: str
    min: float
    max: float
    states: tuple[int, ...]
    #: half-width of the interval by which the bound search could still be wrong (0 when certified)
    bound_gap: float = 0.0

    def to_dict(self) -> dict:
        return {"name": self.name, "expr": self.expr, "min": float(self.min), "max": float(self.max)}


#: the matrices of a local model, in the order the derive and design documents write them
LOCAL_MODEL_KEYS: tuple[str, ...] = ("A", "B", "Bd", "Bf", "W", "a", "G", "Gf", "M")
_REQUIRED = ("A", "B", "Bd", "Bf", "W")


@dataclass(frozen=True)
class LocalModel:
    """One rule: ``dx = (A x + B u + Bd d + Bf f + a) dt + (W x + G u + Gf f + M d2) dw``.

    ``a`` is the affine offset that local linearisation leaves (zero for sector models); ``G``, ``Gf``
    and ``M`` the diffusion terms of Theorem 5 (zero, and ``M`` without columns, when the plant has none).
    The same record is the T-S model's (:attr:`TSModel.local_models`) and the design's
    (``Design.local_models``); every matrix is a float array. Given as ``None``, ``a``, ``G``, ``Gf``
    and ``M`` are zeros of the sizes that ``A``, ``B`` and ``Bf`` imply.

    ``order`` and ``extra`` let a design document read from a file be written back unchanged: ``order``
    is the keys it had (plus ``a``, which documents always carry), ``extra`` any key this version does
    not know. A model made in the toolkit writes :data:`LOCAL_MODEL_KEYS`. For a transition the record
    also answers item access as the design's dicts did (``lm["A"]``, ``lm.get("a")``); new code reads
    attributes.
    """

    A: np.ndarray
    B: np.ndarray
    Bd: np.ndarray
    Bf: np.ndarray
    W: np.ndarray
    a: np.ndarray | None = None
    G: np.ndarray | None = None
    Gf: np.ndarray | None = None
    M: np.ndarray | None = None
    order: tuple[str, ...] = field(default=LOCAL_MODEL_KEYS, repr=False, compare=False)
    extra: dict = field(default_factory=dict, repr=False, compare=False)

    def __post_init__(self) -> None:
        n = np.shape(self.A)[0]
        cols = {"B": np.shape(self.B)[-1], "Bf": np.shape(self.Bf)[-1]}
        zeros = {"a": (n,), "G": (n, cols["B"]), "Gf": (n, cols["Bf"]), "M": (n, 0)}
        for k in LOCAL_MODEL_KEYS:
            v = getattr(self, k)
            object.__setattr__(self, k, np.zeros(zeros[k]) if v is None else np.asarray(v, dtype=float))

    @classmethod
    def from_mapping(cls, doc) -> LocalModel:
        """The record of a document's entry (``{"A": M, ...}``); a record is returned as it is.

        Keeps the entry's key order and any unknown key (see the class docstring). Raises ``KeyError``
        naming a required matrix (A, B, Bd, Bf, W) that ``doc`` lacks.
        """
        if isinstance(doc, cls):
            return doc
        for k in _REQUIRED:
            if k not in doc:
                raise KeyError(k)
        known = {k: doc[k] for k in LOCAL_MODEL_KEYS if k in doc}
        extra = {k: np.asarray(v, dtype=float) for k, v in doc.items() if k not in LOCAL_MODEL_KEYS}
        order = tuple(doc) + (() if "a" in doc else ("a",))
        return cls(**known, order=order, extra=extra)

    def to_dict(self) -> dict:
        """The entry of the derive and design documents: ``{key: matrix as a list of rows}``."""
        return {k: np.asarray(self[k]).tolist() for k in self.order}

    # -- transitional mapping view (item access as the design's dicts had) ----------------------
    def __getitem__(self, key: str) -> np.ndarray:
        if key in LOCAL_MODEL_KEYS:
            return getattr(self, key)
        return self.extra[key]

    def get(self, key: str, default=None):
        """``self[key]`` or ``default`` (transitional: new code reads the attribute)."""
        try:
            return self[key]
        except KeyError:
            return default

    @property
    def has_diffusion_extension(self) -> bool:
        """True when faults, inputs or d2 enter the diffusion (Section 5, Theorem 5)."""
        return bool(np.any(self.G) or np.any(self.Gf) or self.M.size and np.any(self.M))


@dataclass(frozen=True)
class Fidelity:
    """How far the blended T-S model is from the nonlinear plant.

    ``max_abs_error`` is the largest absolute difference of drift or diffusion over
    ``samples`` points of the region; ``trajectory_max_abs_error`` the same along a
    simulated open-loop trajectory from x0 (``trajectory_points`` points, up to
    ``trajectory_horizon``; ``trajectory_stop`` says why it ended early, if it did).
    """

    max_abs_error: float
    samples: int
    drift_max_abs_error: float
    diffusion_max_abs_error: float
    drift_max_rel_error: float
    trajectory_max_abs_error: float
    trajectory_points: int
    trajectory_horizon: float
    #: why the trajectory ends before its horizon ("" if it does not): it left the region far
    #: behind (an unstable open loop), its step budget ran out (a stiff plant) or the integrator failed
    trajectory_stop: str = ""

    def to_dict(self) -> dict:
        return {k: (float(v) if isinstance(v, float) else v) for k, v in self.__dict__.items()}


@dataclass(frozen=True)
class TSModel:
    """A T-S fuzzy model derived from a :class:`~fte_casadi.model.Plant`."""

    plant: Plant
    #: how it was derived (machine-readable; :attr:`method` is the text shown)
    kind: Kind
    premises: tuple[Premise, ...]
    local_models: tuple[LocalModel, ...]
    C: np.ndarray
    Df: np.ndarray
    #: ``x -> premise values`` (q)
    premise_fn: ca.Function
    #: ``premise values -> h`` (r), a convex sum on the premises' bounds
    membership_fn: ca.Function
    fidelity: Fidelity
    #: how the premises were found, for reports (the automatic method's choices; empty otherwise)
    notes: tuple[str, ...] = ()
    #: the groups of premises and the polytope covering each (:mod:`._cover`); empty without premises
    groups: tuple = ()
    #: how the premises were covered (:data:`~fte_casadi.ts._cover.VERTEX_CHOICES`: ``derive(vertices=...)``,
    #: or the default it resolved to); None for a model of operating points, which has no premises to cover
    vertices: str | None = None

    @property
    def rule_premises(self) -> np.ndarray:
        """Premise values of each rule's vertex, (r, q) (sector models)."""
        from ._cover import rule_vertices_of

        return rule_vertices_of(self.groups, len(self.premises))

    @property
    def rule_distances(self) -> np.ndarray | None:
        """Per rule, how far its vertex lies from the premises' image over the region, relative to the
        image's extent (0: a state of the region takes it); None when the model has no groups."""
        from ._cover import rule_distances

        return rule_distances(self.groups) if self.groups else None

    @property
    def method(self) -> str:
        """How the model was derived, as reports and the derive document show it."""
        return METHOD_TEXT[self.kind]

    @property
    def r(self) -> int:
        return len(self.local_models)

    @property
    def n(self) -> int:
        return self.C.shape[1]

    @property
    def m(self) -> int:
        return self.local_models[0].B.shape[1]

    @property
    def p(self) -> int:
        return self.C.shape[0]

    @property
    def ld(self) -> int:
        return self.local_models[0].Bd.shape[1]

    @property
    def lf(self) -> int:
        return self.local_models[0].Bf.shape[1]

    def memberships(self, x) -> np.ndarray:
        """Membership values at state(s) ``x`` (shape (n,) or (n, N)) -> (r,) or (r, N)."""
        x = np.asarray(x, dtype=float)
        h = np.array(self.membership_fn(self.premise_fn(x)))
        return h.ravel() if x.ndim == 1 else h

    def to_control(self) -> list:
        """One ``control.StateSpace`` per rule: ``dx = A_i x + B_i u + Bd_i d + Bf_i f``, ``y = C x + Df f``.

        Inputs ``[u; d; f]`` and outputs ``y`` carry the plant's signal names, so that
        ``control.poles``, ``step_response`` or ``bode_plot`` work on each rule. The affine offset
        of a linearised rule and the diffusion are left out. Needs python-control
        (``pip install 'fte_casadi[control]'``).
        """
        from ..interop import local_model_ss

        pl = self.plant
        names = {"inputs": list(pl.input_names), "unknown_inputs": list(pl.unknown_input_names),
                 "faults": list(pl.fault_names), "outputs": list(pl.output_names), "states": list(pl.state_names)}  # fmt: skip
        return [
            local_model_ss(lm, self.C, self.Df, names, i, pl.name) for i, lm in enumerate(self.local_models)
        ]

    def _groups_dict(self) -> dict:
        if not self.groups:
            return {}
        names = [p.name for p in self.premises]
        return {
            "premise_groups": [g.to_dict(names) for g in self.groups],
            "rule_premises": self.rule_premises.tolist(),
            "rule_vertex_distance": self.rule_distances.tolist(),
        }

    def to_dict(self) -> dict:
        """The derive document (docs/interface.md)."""
        return {
            "plant": self.plant.name,
            "method": self.method,
            "rules": self.r,
            "premises": [p.to_dict() for p in self.premises],
            "local_models": [lm.to_dict() for lm in self.local_models],
            "C": self.C.tolist(),
            "Df": self.Df.tolist(),
            "fidelity": self.fidelity.to_dict(),
            "premises_found_automatically": self.kind == "sector_auto",
            "vertices": self.vertices,
            **self._groups_dict(),
            "notes": list(self.notes),
            "states": list(self.plant.state_names),
            "inputs": list(self.plant.input_names),
            "faults": list(self.plant.fault_names),
            "outputs": list(self.plant.output_names),
        }


def as_model(obj, where: str) -> TSModel:
    """``obj`` when it is a :class:`TSModel`; else :class:`~fte_casadi.errors.ParameterError` saying what
    ``where`` (``design()``, ``explore()``) takes, and how to make it from a plant."""
    from ..errors import ParameterError

    if isinstance(obj, TSModel):
        return obj
    if isinstance(obj, Plant):
        raise ParameterError(
            f"{where} takes the T-S model of a plant, not the plant itself: {where.split('(')[0]}(derive(plant), "
            "...), with derive from fte_casadi"
        )
    raise ParameterError(f"{where} takes a T-S model (fte_casadi.derive(plant)); got {type(obj).__name__}")
