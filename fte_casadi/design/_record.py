"""The design record: a frozen object with atomic JSON save/load exactly as docs/interface.md describes it.

Every key of the design document (docs/interface.md) is here under its contract name. Extra keys
(all additions, none renamed) carry what the simulator and the C generator need to rebuild
the step without the plant's Python code: the affine offsets ``a`` of each local model, the
reference input, the scheduling map (y, xhat) -> h as an instruction tape of arithmetic operations
(``scheduling_ops``, :mod:`fte_casadi.model._tape`), signal names, and the certificate's full report.

A document is data (docs/interface.md, "Trust model"): reading one never deserialises an executable
object. Documents also carry ``scheduling``, the same map as a serialised CasADi Function, for older
versions of fte; it is never read back. ``schema`` is the document's version (:data:`SCHEMA`) and
``plant_hash`` the fingerprint of the plant's equations it was designed for
(:mod:`fte_casadi.model._fingerprint`).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from .._atomic import atomic_write_text
from ..errors import DesignFileError
from ..ts import LocalModel
from ._parts import Dims, Observer, Params, _Record

__all__ = ["Design", "Dims", "Params", "Observer"]  # public: docs/api.md

#: the version of the design document this fte writes (documents without ``schema`` predate it: 1)
SCHEMA = 2

REQUIRED_KEYS = (
    "plant",
    "variant",
    "solver",
    "params",
    "dims",
    "premises",
    "local_models",
    "C",
    "Df",
    "H",
    "T",
    "X",
    "P",
    "K",
    "Kf",
    "Pbar",
    "Q",
    "N",
    "theta",
    "L1",
    "L2",
    "R",
    "Ls",
    "checks",
    "timings",
)
_MATS = ("C", "Df", "H", "T", "X", "P", "Kf", "Pbar", "N", "Ls")
_LISTS = ("K", "Q", "L1", "L2", "R")


def _arr(x) -> np.ndarray:
    return np.asarray(x, dtype=float)


@dataclass(frozen=True)
class Design:
    """A certified (or honestly uncertified) observer/controller design for one plant.

    ``params``, ``dims`` and ``observer`` are typed frozen records (:class:`~fte_casadi.design._parts.Params`,
    :class:`~fte_casadi.design._parts.Dims`, :class:`~fte_casadi.design._parts.Observer`), read by attribute:
    ``d.dims.n``, ``d.params.sigma``, ``d.observer.alpha``; a plain dict given for one (for example in
    ``dataclasses.replace(d, params={...})``) becomes the record. ``checks`` stays a dict (its key set is open; see the records' module).
    """

    plant: str
    plant_spec: str
    variant: str
    solver: str
    params: Params
    dims: Dims
    premises: list
    #: one per rule, the T-S model's own records (:class:`~fte_casadi.ts._model.LocalModel`)
    local_models: tuple[LocalModel, ...]
    C: np.ndarray
    Df: np.ndarray
    H: np.ndarray
    T: np.ndarray
    X: np.ndarray
    P: np.ndarray
    K: tuple
    Kf: np.ndarray
    Pbar: np.ndarray
    Q: tuple
    N: np.ndarray
    theta: float
    L1: tuple
    L2: tuple
    R: tuple
    Ls: np.ndarray
    checks: dict
    timings: dict
    u_ref: np.ndarray
    #: the scheduling map (y, xhat) -> h: given in code as a casadi Function (or its serialisation); from
    #: a document, the serialised Function older versions wrote, kept as text and never deserialised
    scheduling: object
    names: dict = field(default_factory=dict)  # states, inputs, outputs, faults, units
    certified: bool = True
    status: list = field(default_factory=list)  # what was done: solver statuses, retries, fallbacks
    x_ref: np.ndarray | None = None
    #: conic solves per step (the rest of the design is numpy: centring and phase-1 decisions)
    solves: dict = field(default_factory=dict)
    #: the observer decay rate alpha, the largest feasible one, and why alpha is what it is
    observer: Observer = field(default_factory=Observer)
    #: actuator limits, (m, 2) rows [lo, hi] with -inf/inf for an open side; None: no limits
    input_limits: np.ndarray | None = None
    #: one Kf_i = -pinv(B_i) Bf_i per rule where they differ (the step then blends them, Kf(h) =
    #: sum_i h_i Kf_i); None when one Kf serves every rule (``Kf`` is then that one, else rule 1's)
    Kf_rules: tuple | None = None
    #: parameters the tool chose itself (none given by the user or the plant): {name: {"value", "why"}}
    params_chosen: dict = field(default_factory=dict)
    #: the nominal initial state x0 the simulation starts the observer from (its scenario's, else the
    #: plant's); the generated C's ``init_from_y`` starts there: z0 = [x0; 0; 0] - H y0. None: zeros
    x0: np.ndarray | None = None
    #: Remark 5's fallback (:mod:`fte_casadi.design._remark5`): {"used": True, "unknown_inputs": [...],
    #: "gain": [one per undecoupled direction], "d_bound", "Bdu", "M", ...}; empty when not used
    remark5: dict = field(default_factory=dict)
    #: certified performance bounds at the design (:mod:`fte_casadi.design.core._bounds`): {"fault_error": {...}}
    bounds: dict = field(default_factory=dict)
    #: the scheduling map as data (:func:`fte_casadi.model._tape.write_tape`); None: a document older than it
    scheduling_ops: dict | None = None
    #: the fingerprint of the plant's equations (:func:`fte_casadi.model._fingerprint.plant_fingerprint`);
    #: empty for documents older than it
    plant_hash: dict = field(default_factory=dict)
    #: accommodation after detection (:mod:`fte_casadi.sim._accommodate`): {"rule": "explain", "thresholds": [one
    #: per fault], "crosstalk": lf x lf, "release": ratio, ...}: fault j is compensated in u while |fhat_j| >=
    #: threshold_j + sum_q crosstalk[j][q] |fhat_q| (+ overshoot_j m_j with "overshoot": per fault, and
    #: "memory_time": the gate then holds each estimate's recent extremes, :attr:`remembers`) (what ``fte design``
    #: writes where the faults' estimates cross-talk); or {"rule": "isolate", ...}: fault j switches on when |fhat_j| >= threshold_j and its normalised
    #: residual |fhat_j| / threshold_j is the largest (``fte simulate --accommodate``); with a release ratio below
    #: 1 either stays on until that ratio falls below it (:func:`fte_casadi.step.accommodation_gate`; no "release":
    #: 1, the memoryless gate); with "crosstalk_held" (rule "explain") each cross-talk term is at most
    #: crosstalk_held[j][q] times fault q's held estimate; "never": the faults never compensated (their
    #: compensation measured worse than none in their own windows); None: every estimate is compensated always
    #: (the paper)
    accommodation: dict | None = None
    #: how the T-S model's premises were covered (``derive(vertices=...)``: grouped, box or fewest); loading
    #: re-derives the plant's model with it. None: the derivation's default (a document older than the key, or a
    #: model of operating points)
    vertices: str | None = None
    #: the x block of the Lyapunov function ``V = x^T P29 x + e^T Pbar e`` of Theorem 1's (29), for a design that
    #: (29) certifies where (45)-(46) do not (docs/design.md, "When the diffusion is the cause"); None: the design
    #: is certified by (45)-(46) (and (29), which they imply, is evaluated at ``P = X^-1``)
    P29: np.ndarray | None = None
    #: how a loaded document read (not a document key): {"source", "schema", "certified"}, the last as the
    #: document wrote it (None: absent); empty for a design made in this process
    loaded: dict = field(default_factory=dict, compare=False, repr=False)

    def __post_init__(self) -> None:
        if self.scheduling_ops is None and not self.loaded:
            # made in code (a design, a test fixture): the map is a Function, or its serialisation made by the
            # same program; a document's (self.loaded set) is never deserialised
            import casadi as ca

            from ..model import write_tape

            fn = self.scheduling
            if isinstance(fn, str) and fn:
                fn = ca.Function.deserialize(fn)
            if isinstance(fn, ca.Function):
                object.__setattr__(self, "scheduling_ops", write_tape(fn))
                object.__setattr__(self, "scheduling", fn.serialize())
        # dicts (older callers, dataclasses.replace(d, params={...})) become the typed records
        for name, rec in (("params", Params), ("dims", Dims), ("observer", Observer)):
            value = getattr(self, name)
            if not isinstance(value, rec):
                object.__setattr__(self, name, rec.from_mapping(value))
        # and so do dicts given for the local models (a record is kept as it is)
        object.__setattr__(self, "local_models", tuple(map(LocalModel.from_mapping, self.local_models)))

    # -- convenience ---------------------------------------------------------------------
    @property
    def r(self) -> int:
        return int(self.dims.r)

    @property
    def nbar(self) -> int:
        return int(self.dims.nbar)

    @property
    def latched(self) -> bool:
        """True when the accommodation gate has hysteresis (a release ratio below 1): its latches are state."""
        return self.accommodation is not None and float(self.accommodation.get("release", 1.0)) < 1.0

    @property
    def remembers(self) -> bool:
        """True when the gate holds each estimate's recent extremes (rule ``explain`` with ``overshoot``)."""
        return self.accommodation is not None and "overshoot" in self.accommodation

    @property
    def nz(self) -> int:
        """Length of the step's state: ``z`` (nbar), then with a latched gate one latch (0 or 1) per fault, then
        with a remembering gate two memories per fault (its estimate's recent largest and smallest, decaying)."""
        lf = int(self.dims.lf)
        return self.nbar + (lf if self.latched else 0) + (2 * lf if self.remembers else 0)

    def sliding_gain(self) -> np.ndarray:
        """The gain of each sliding variable: Remark 5's per-direction gains for the undecoupled part of d
        (first), then ``delta + eps`` for each fault's ``f''`` (docs/method.md, sliding surface (19)-(21))."""
        lf = int(self.dims.lf)
        base = np.full(lf, float(self.params.delta) + float(self.params.epsilon))
        if not self.remark5.get("used"):
            return base
        return np.concatenate([_arr(self.remark5["gain"]).ravel(), base])

    def kf(self, i: int) -> np.ndarray:
        """Rule ``i``'s fault-compensation gain: its own where the rules differ, else the common Kf."""
        return _arr(self.Kf if self.Kf_rules is None else self.Kf_rules[i])

    @property
    def xbar0(self) -> np.ndarray:
        """The nominal augmented initial state ``[x0; 0; 0]`` (zeros when no x0 is recorded)."""
        out = np.zeros(self.nbar)
        if self.x0 is not None:
            out[: int(self.dims.n)] = _arr(self.x0)
        return out

    def observer_start(self, y0, xbar0=None) -> np.ndarray:
        """``z0 = xbar0 - H y0`` (xbar0 None: :attr:`xbar0`), summed in the order of the generated C's
        ``init_from_y`` so that both give the same bits (at that start the residual ``y - Cbar xbarhat``
        is zero up to round-off, and ``sgn`` of a round-off decides the first sliding term). With a latched
        accommodation gate (:attr:`latched`) the step's state goes on with the latches, all off (0), as the C's
        ``init`` sets them: the result has :attr:`nz` values."""
        H = _arr(self.H)
        y = [float(v) for v in np.ravel(y0)]
        xb = self.xbar0 if xbar0 is None else _arr(xbar0).ravel()
        out = np.zeros(self.nz)
        for i in range(H.shape[0]):
            hy = 0.0
            for j, yj in enumerate(y):
                hy += float(H[i, j]) * yj
            out[i] = float(xb[i]) - hy
        return out

    def scheduling_function(self):
        """The CasADi Function ``(y, xhat) -> h``, replayed from :attr:`scheduling_ops` (data, never a
        deserialised Function). A document older than ``scheduling_ops`` needs its plant:
        :func:`fte_casadi.trust.with_plant` rebuilds the map from it."""
        from ..model import read_tape

        if self.scheduling_ops is None:
            raise DesignFileError(
                f"the design of {self.plant} carries its scheduling map only as a serialised CasADi Function (a "
                "document older than 'scheduling_ops'), which fte does not deserialise: it can load a shared library. "
                "Name the plant the map is rebuilt from (fte: --plant FILE.py:FUNCTION; Python: "
                "fte_casadi.trust.with_plant(design, plant)), or make the document again with `fte design`"
            )
        return read_tape(self.scheduling_ops, "scheduling")

    def to_control(self, i: int = 0, j: int = 0, sample_time: float | None = None):
        """The closed loop of plant rule ``i``, observer rule ``i`` and gain ``K_j`` as a ``control.StateSpace``.

        States ``[x; z]``; inputs ``[u_ref; d; f]`` (the reference input, unknown inputs, faults);
        outputs ``[y; u; xbarhat]``. The controller is the tolerant one, ``u = u_ref + K_j xhat +
        Kf fhat`` with ``xbarhat = z + H y``. Left out: the sliding term ``Ls us`` (discontinuous),
        the affine offsets of linearised models and the actuator limits (the model is linear). Its
        poles are ``eig(A_i + B_i K_j)`` and ``eig(R_i)`` (the observer error decouples). With
        ``sample_time``: the loop as the generated C runs it, the plant by zero-order hold and the observer
        by the explicit Euler step of docs/method.md. Needs python-control (``fte_casadi[control]``).
        The former keyword ``dt`` was removed in 0.2.0: giving it is a ``TypeError``.
        """
        from ..interop import closed_loop_ss

        return closed_loop_ss(self, i, j, sample_time)

    def affine(self, i: int) -> np.ndarray:
        """Affine offset ``a_i`` of rule ``i`` (zeros for sector models)."""
        return self.local_models[i].a

    # -- JSON ----------------------------------------------------------------------------
    def to_dict(self) -> dict:
        out = {
            "plant": self.plant,
            "variant": self.variant,
            "solver": self.solver,
            "params": self.params.to_dict(),
            "dims": self.dims.to_dict(),
            "premises": self.premises,
            "local_models": [lm.to_dict() for lm in self.local_models],
        }
        for k in _MATS:
            out[k] = _arr(getattr(self, k)).tolist()
        for k in _LISTS:
            out[k] = [_arr(M).tolist() for M in getattr(self, k)]
        out["theta"] = float(self.theta)
        nonfinite: dict[str, str] = {}
        out["checks"] = _jsonable(self.checks, "checks", nonfinite)
        out["timings"] = _jsonable({k: float(v) for k, v in self.timings.items()}, "timings", nonfinite)
        out["plant_spec"] = self.plant_spec
        out["u_ref"] = _arr(self.u_ref).tolist()
        out["x_ref"] = None if self.x_ref is None else _arr(self.x_ref).tolist()
        if self.x0 is not None:
            out["x0"] = _arr(self.x0).tolist()
        if self.params_chosen:
            out["params_chosen"] = _jsonable(self.params_chosen, "params_chosen", nonfinite)
        if self.bounds:
            out["bounds"] = _jsonable(self.bounds, "bounds", nonfinite)
        if self.Kf_rules is not None:
            out["Kf_rules"] = [_arr(M).tolist() for M in self.Kf_rules]
        if self.remark5.get("used"):
            out["remark5"] = _jsonable(self.remark5, "remark5", nonfinite)
        out["scheduling"] = self.scheduling if isinstance(self.scheduling, str) else ""
        if self.scheduling_ops is not None:
            out["scheduling_ops"] = self.scheduling_ops
        out["schema"] = SCHEMA
        if self.vertices is not None:
            out["vertices"] = self.vertices
        if self.P29 is not None:
            out["P29"] = _arr(self.P29).tolist()
        if self.plant_hash:
            out["plant_hash"] = dict(self.plant_hash)
        if self.accommodation is not None:
            out["accommodation"] = _jsonable(self.accommodation, "accommodation", nonfinite)
        out["names"] = self.names
        out["certified"] = bool(self.certified)
        out["status"] = list(self.status)
        out["solves"] = {k: int(v) for k, v in self.solves.items()}
        out["observer"] = _jsonable(self.observer.to_dict(), "observer", nonfinite)
        out["input_limits"] = (
            None
            if self.input_limits is None
            else _jsonable(np.asarray(self.input_limits, float), "input_limits", nonfinite)
        )
        if nonfinite:
            out["nonfinite"] = nonfinite
        return out

    def to_json(self) -> str:
        """The design document as JSON text.

        One policy for non-finite numbers: in the reports (``checks``, ``bounds``, ``timings``, ``observer``,
        ``input_limits``, ...) a NaN or an infinity is written as ``null`` and the document's ``nonfinite``
        entry names it with what it was and why (``{"checks.lmi_max_eig.45": "NaN: ..."}``); reading gives
        the NaN or infinity back. A matrix, a parameter or a size that is not finite makes the design
        unusable: writing it is refused (``ValueError`` naming the key). Never a finite stand-in.
        """
        doc = self.to_dict()
        bad = _first_nonfinite(doc)
        if bad is not None:
            raise ValueError(f"{bad!r} holds a NaN or infinite entry")
        return json.dumps(doc, indent=1, allow_nan=False)

    def save(self, path: str | os.PathLike) -> None:
        """Write the design document atomically (an existing file survives a failed run); refuse, naming
        the key, a design whose matrices or parameters are not finite (see :meth:`to_json`)."""
        try:
            text = self.to_json()
        except ValueError as exc:
            raise DesignFileError(
                f"the design holds a non-finite number and cannot be written as JSON ({exc}); its matrices "
                "are unusable: make the design again"
            ) from None
        try:
            atomic_write_text(path, text)
        except OSError as exc:
            raise DesignFileError(
                f"cannot write the design to {path}: {exc.strerror or exc}; choose a writable path with -o"
            ) from None

    def save_mat(self, path: str | os.PathLike) -> None:
        """Write the design document as a MAT file (:mod:`fte_casadi.design._matfile`), atomically."""
        from ._matfile import save_mat

        save_mat(self.to_dict(), path)

    @classmethod
    def from_dict(cls, doc: dict, source: str = "design document") -> Design:
        if not isinstance(doc, dict):
            raise DesignFileError(f"{source} is not a JSON object")
        missing = [k for k in REQUIRED_KEYS + ("u_ref", "scheduling") if k not in doc]
        if missing:
            raise DesignFileError(
                f"{source} lacks key(s) {missing}: it is not a complete fte design document; "
                "make it again with `fte design PLANT -o FILE`"
            )
        for name, rec in (("params", Params), ("dims", Dims), ("observer", Observer)):
            entry = doc.get(name) or {}
            if not isinstance(entry, dict):
                raise DesignFileError(
                    f"{source}: {name!r} must be a JSON object; make it again with `fte design`"
                )
            lack = rec.missing(entry)
            if lack:
                raise DesignFileError(f"{source}: {name!r} lacks {lack}; make it again with `fte design`")
        from ._docchecks import check_document

        check_document(doc, source)
        doc = _restore_nonfinite(doc)
        if isinstance(doc.get("schema"), int) and doc["schema"] > SCHEMA:
            raise DesignFileError(
                f"{source} is a design document of schema {doc['schema']}, written by a newer fte than this one "
                f"(which reads schema {SCHEMA} and older); upgrade fte_casadi"
            )
        ops = doc.get("scheduling_ops")
        if ops is not None and not isinstance(ops, dict):
            raise DesignFileError(
                f"{source}: 'scheduling_ops' must be a JSON object; make it again with `fte design`"
            )
        try:
            params = Params.from_mapping(doc["params"])
            dims = Dims.from_mapping(doc["dims"])
            observer = Observer.from_mapping(doc.get("observer"))
            r = int(dims.r)
            kw = {k: _finite(source, k, doc[k]) for k in _MATS}
            for k in _LISTS:
                v = doc[k]
                if not isinstance(v, list) or len(v) != r:
                    raise DesignFileError(f"{source}: {k!r} must be a list of r = {r} matrices")
                kw[k] = tuple(_finite(source, f"{k}[{i}]", M) for i, M in enumerate(v))
            lms = tuple(_local_model(source, i, lm) for i, lm in enumerate(doc["local_models"]))
            if len(lms) != r:
                raise DesignFileError(f"{source}: 'local_models' must hold r = {r} models")
            theta = float(doc["theta"])
            u_ref = _finite(source, "u_ref", doc["u_ref"])
        except (TypeError, KeyError, ValueError) as exc:
            if isinstance(exc, DesignFileError):
                raise
            raise DesignFileError(f"{source} is malformed ({exc}); make it again with `fte design`") from None
        return cls(
            plant=str(doc["plant"]),
            plant_spec=str(doc.get("plant_spec", doc["plant"])),
            variant=str(doc["variant"]),
            solver=str(doc["solver"]),
            params=params,
            dims=dims,
            premises=list(doc["premises"]),
            local_models=lms,
            theta=theta,
            checks=dict(doc["checks"]),
            timings=dict(doc["timings"]),
            u_ref=u_ref,
            x_ref=None if doc.get("x_ref") is None else _arr(doc["x_ref"]),
            params_chosen=dict(doc.get("params_chosen", {})),
            bounds=dict(doc.get("bounds") or {}),
            x0=None if doc.get("x0") is None else _finite(source, "x0", doc["x0"]),
            Kf_rules=None
            if doc.get("Kf_rules") is None
            else tuple(_finite(source, "Kf_rules", M) for M in doc["Kf_rules"]),
            scheduling=doc["scheduling"] if isinstance(doc["scheduling"], str) else "",
            scheduling_ops=ops,
            plant_hash=dict(doc.get("plant_hash") or {}),
            vertices=doc.get("vertices"),
            P29=_p29(source, doc.get("P29"), int(dims.n)),
            accommodation=_accommodation(source, doc.get("accommodation"), int(dims.lf)),
            loaded={"source": source, "schema": int(doc.get("schema", 1)), "certified": doc.get("certified")},
            names=dict(doc.get("names", {})),
            certified=doc.get("certified") is True,
            status=list(doc.get("status", [])),
            solves=dict(doc.get("solves", {})),
            observer=observer,
            input_limits=_limits(source, doc.get("input_limits"), int(dims.m)),
            remark5=_remark5(source, doc.get("remark5"), kw["Ls"].shape[1] - int(dims.lf)),
            **kw,
        )

    @classmethod
    def load(cls, path: str | os.PathLike) -> Design:
        """Read a design document, refusing a missing, truncated or corrupt file with a clear message
        (:func:`~fte_casadi.design._docchecks.read_document`)."""
        from ._docchecks import read_document

        p = Path(path)
        doc = read_document(p)
        return cls.from_dict(doc, source=f"design file {str(p)!r}")


def _p29(source: str, value, n: int) -> np.ndarray | None:
    """The document's ``P29`` (Theorem 1's x block of V): None, or an n x n matrix of finite numbers."""
    if value is None:
        return None
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        a = np.zeros(0)
    if a.shape != (n, n):
        raise DesignFileError(f"{source}: 'P29' must be a {n} x {n} matrix of finite numbers (Theorem 1's x block of "
                              f"V); got shape {a.shape}")  # fmt: skip
    return _finite(source, "P29", a)


def _accommodation(source: str, value, lf: int) -> dict | None:
    """The document's ``accommodation``: None, or a rule fte knows with ``lf`` finite positive thresholds."""
    if value is None:
        return None
    if not isinstance(value, dict) or value.get("rule") not in ("isolate", "explain"):
        raise DesignFileError(
            f"{source}: 'accommodation' must be null or an object with rule 'isolate' or 'explain'; got {value!r}"
        )
    thr = value.get("thresholds")
    ok = (
        isinstance(thr, list)
        and len(thr) == lf
        and all(
            isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) and v > 0 for v in thr
        )
    )
    if not ok:
        raise DesignFileError(
            f"{source}: 'accommodation.thresholds' must be {lf} finite positive numbers (one per fault); got {thr!r}"
        )
    out = {**value, "thresholds": [float(v) for v in thr]}
    if (
        value["rule"] == "explain"
    ):  # the observer's cross-talk ratios (design/_isolation.py), checked on load too
        ct = value.get("crosstalk")
        try:
            a = np.array(ct, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if a.shape != (lf, lf) or not np.all(np.isfinite(a)) or np.any(a < 0):
            raise DesignFileError(
                f"{source}: 'accommodation.crosstalk' must be a {lf} x {lf} matrix of finite numbers >= 0 (the "
                f"observer's cross-talk ratios); got {ct!r}"
            )
        out["crosstalk"] = a.tolist()
    if "crosstalk_held" in value:  # the cross-talk against the held estimates (design/_isolation.py)
        ch = value["crosstalk_held"]
        try:
            a = np.array(ch, dtype=float)
        except (TypeError, ValueError):
            a = np.zeros(0)
        if value["rule"] != "explain" or a.shape != (lf, lf) or not np.all(np.isfinite(a)) or np.any(a < 0):
            raise DesignFileError(
                f"{source}: 'accommodation.crosstalk_held' must be a {lf} x {lf} matrix of finite numbers >= 0 (the "
                f"observer's cross-talk against the held estimates, rule 'explain' only); got {ch!r}"
            )
        out["crosstalk_held"] = a.tolist()
    if "never" in value:  # the faults never compensated (their compensation measured worse than none)
        nv = value["never"]
        if not (isinstance(nv, list) and len(set(nv)) == len(nv)
                and all(isinstance(j, int) and not isinstance(j, bool) and 0 <= j < lf for j in nv)):  # fmt: skip
            raise DesignFileError(
                f"{source}: 'accommodation.never' must be a list of distinct fault indices in 0..{lf - 1} (the faults "
                f"never compensated); got {nv!r}"
            )
        out["never"] = sorted(nv)
    if "release" in value:  # absent (documents older than it): 1, the memoryless gate
        rel = value["release"]
        if not (
            isinstance(rel, (int, float)) and not isinstance(rel, bool) and np.isfinite(rel) and 0 < rel <= 1
        ):
            raise DesignFileError(
                f"{source}: 'accommodation.release' must be a number in (0, 1] (the ratio |fhat_j| / threshold_j "
                f"below which a compensated fault is released; 1: no hysteresis); got {rel!r}"
            )
        out["release"] = float(rel)
    return out


def _limits(source: str, value, m: int) -> np.ndarray | None:
    """``input_limits`` of a document: None, or m rows [lo, hi] with null for an open side."""
    if value is None:
        return None
    try:
        a = np.array([[(-np.inf if k == 0 else np.inf) if v is None else float(v) for k, v in enumerate(row)]
                      for row in value], dtype=float)  # fmt: skip
    except (TypeError, ValueError):
        raise DesignFileError(
            f"{source}: 'input_limits' must be a list of [lower, upper] pairs (null: open)"
        ) from None
    if a.shape != (m, 2) or np.any(np.isnan(a)) or not np.all(a[:, 0] < a[:, 1]):
        raise DesignFileError(
            f"{source}: 'input_limits' must hold {m} pairs [lower, upper] with lower < upper"
        )
    return a


def _remark5(source: str, value, k: int) -> dict:
    """``remark5`` of a document: absent or {"used": false} (then Ls has lf columns), or the fallback with
    one gain per undecoupled direction (Ls has lf + that many columns)."""
    if not value or not value.get("used"):
        if k != 0:
            raise DesignFileError(
                f"{source}: 'Ls' has {k} more columns than faults but 'remark5' is not used"
            )
        return {}
    gain = _finite(source, "remark5.gain", value.get("gain", [])).ravel()
    if gain.size != k or np.any(gain < 0):
        raise DesignFileError(
            f"{source}: 'remark5.gain' must hold {k} non-negative numbers, one per undecoupled direction (the "
            "columns of 'Ls' beyond the faults')"
        )
    return dict(value)


def _local_model(source: str, i: int, entry) -> LocalModel:
    """Rule ``i``'s local model of a document: every matrix finite, A, B, Bd, Bf, W present."""
    if not isinstance(entry, dict):
        raise DesignFileError(
            f"{source}: 'local_models[{i}]' must be a JSON object of matrices (A, B, Bd, Bf, W, ...)"
        )
    try:
        return LocalModel.from_mapping(
            {k: _finite(source, f"local_models[{i}].{k}", v) for k, v in entry.items()}
        )
    except KeyError as exc:
        raise DesignFileError(
            f"{source}: 'local_models[{i}]' lacks the matrix {exc}; make it again with `fte design`"
        ) from None


def _first_nonfinite(obj, path: str = "") -> str | None:
    """The path of the first NaN or infinity left in a document (where nothing writes it as null)."""
    if isinstance(obj, dict):
        for k, v in obj.items():
            bad = _first_nonfinite(v, f"{path}.{k}" if path else str(k))
            if bad is not None:
                return bad
    elif isinstance(obj, (list, tuple)):
        for k, v in enumerate(obj):
            bad = _first_nonfinite(v, f"{path}[{k}]")
            if bad is not None:
                return bad
    elif isinstance(obj, float) and not math.isfinite(obj):
        return path
    return None


def _finite(source: str, key: str, value) -> np.ndarray:
    a = np.asarray(value, dtype=float)
    if not np.all(np.isfinite(a)):
        raise DesignFileError(f"{source}: {key!r} holds a NaN or infinite entry; the design is unusable")
    return a


#: why a number of a document's section is not finite, by the longest matching path prefix
_NONFINITE_WHY = {
    "checks.lmi_max_eig": "the LMI's largest eigenvalue was not evaluated at a finite point; it is no certificate",
    "checks": "the check was not evaluated at a finite point",
    "bounds": "the bound was not computed at a finite point",
    "input_limits": "no limit on this side",
}


def _why_nonfinite(path: str, v: float) -> str:
    kind = "NaN" if math.isnan(v) else ("+inf" if v > 0 else "-inf")
    prefix = max((p for p in _NONFINITE_WHY if path == p or path.startswith(p + ".")), key=len, default=None)
    return f"{kind}: {_NONFINITE_WHY[prefix] if prefix else 'not a finite number'}"


def _jsonable(obj, path: str, nonfinite: dict):
    """``obj`` as JSON values: a non-finite number becomes ``null`` and ``nonfinite[path]`` says what it was
    and why (:func:`_restore_nonfinite` reads it back); a finite stand-in is never written."""
    if isinstance(obj, _Record):
        obj = obj.to_dict()
    if isinstance(obj, dict):
        return {str(k): _jsonable(v, f"{path}.{k}", nonfinite) for k, v in obj.items()}
    if isinstance(obj, (list, tuple, np.ndarray)):
        return [_jsonable(v, f"{path}.{k}", nonfinite) for k, v in enumerate(obj)]
    if isinstance(obj, (bool, np.bool_)):
        return bool(obj)
    if isinstance(obj, (np.floating, float)):
        v = float(obj)
        if math.isfinite(v):
            return v
        nonfinite[path] = _why_nonfinite(path, v)
        return None
    if isinstance(obj, (np.integer,)):
        return int(obj)
    return obj


def _restore_nonfinite(doc: dict) -> dict:
    """``doc`` with each null that its ``nonfinite`` entry explains read back as NaN, +inf or -inf (the
    sections are copied; the rest is shared). A path that does not lead to a null is ignored."""
    notes = doc.get("nonfinite")
    if not isinstance(notes, dict) or not notes:
        return doc
    doc = dict(doc)
    copied: set[str] = set()
    for path, why in notes.items():
        parts = str(path).split(".")
        if not parts or parts[0] not in doc or not isinstance(why, str):
            continue
        kind = why.split(":", 1)[0].strip()
        value = {"NaN": math.nan, "+inf": math.inf, "-inf": -math.inf}.get(kind)
        if value is None:
            continue
        if parts[0] not in copied:
            doc[parts[0]] = json.loads(json.dumps(doc[parts[0]]))  # a deep copy of JSON data
            copied.add(parts[0])
        node = doc
        for p in parts[:-1]:
            node = node.get(p) if isinstance(node, dict) else (
                node[int(p)] if isinstance(node, list) and p.isdigit() and int(p) < len(node) else None
            )  # fmt: skip
            if node is None:
                break
        last = parts[-1]
        if isinstance(node, dict) and last in node and node[last] is None:
            node[last] = value
        elif isinstance(node, list) and last.isdigit() and int(last) < len(node) and node[int(last)] is None:
            node[int(last)] = value
    return doc
