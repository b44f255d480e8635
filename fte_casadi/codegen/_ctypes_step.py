"""Load a compiled generated step with ctypes and run it against the in-process CasADi step.

Used by the tests (the way CasADi tests its own code generation: compile, load back, compare)
and by the benchmarks.
"""

from __future__ import annotations

import ctypes
import os

import numpy as np

from ..design import Design
from ..errors import CodegenError
from ..step import step_function
from ._generate import c_name

__all__ = []  # public: docs/api.md

_CTYPES = {"double": ctypes.c_double, "float": ctypes.c_float}
_NP = {"double": np.float64, "float": np.float32}


class CStep:
    """The generated ``fte_NAME_init``/``fte_NAME_step`` of a shared library, callable from numpy."""

    def __init__(self, lib_path: str | os.PathLike, design: Design, real: str = "double"):
        self.lib = ctypes.CDLL(str(lib_path))
        self.real = real
        self.dtype = _NP[real]
        self.nbar, self.p, self.m = int(design.dims.nbar), int(design.dims.p), int(design.dims.m)
        self.nz = (
            design.nz
        )  # z, then a latched accommodation gate's latches, then a remembering gate's memories
        self.lf, self.latched = int(design.dims.lf), design.latched
        name = c_name(design.plant)
        self._init = getattr(self.lib, f"fte_{name}_init")
        self._step = getattr(self.lib, f"fte_{name}_step")
        ptr = ctypes.POINTER(_CTYPES[real])
        self._init.argtypes = [ctypes.c_void_p, ptr]
        self._init.restype = ctypes.c_int
        self._init_from_y = getattr(self.lib, f"fte_{name}_init_from_y")
        self._init_from_y.argtypes = [ctypes.c_void_p, ptr, ptr]
        self._init_from_y.restype = ctypes.c_int
        self._step.argtypes = [ctypes.c_void_p, ptr, ptr, ptr, ptr]
        self._step.restype = ctypes.c_int
        self._ptr = ptr
        # the struct starts with z[nz], z_next[nz]; work arrays follow (generously sized buffer)
        self.state = (ctypes.c_char * 65536)()

    def _p(self, a: np.ndarray):
        return a.ctypes.data_as(self._ptr)

    def init(self, z0=None) -> int:
        """``fte_NAME_init``: z0 (None: zeros); its return code (0, or 1/3 for a refused z0)."""
        if z0 is None:
            return int(self._init(ctypes.byref(self.state), None))
        z = np.ascontiguousarray(z0, dtype=self.dtype)
        return int(self._init(ctypes.byref(self.state), self._p(z)))

    def init_from_y(self, y0, xbar0=None) -> int:
        """``fte_NAME_init_from_y``: z0 = xbar0 - H y0 (xbar0 None: the design's nominal one); its return code."""
        y = np.ascontiguousarray(y0, dtype=self.dtype)
        xb = None if xbar0 is None else self._p(np.ascontiguousarray(xbar0, dtype=self.dtype))
        return int(self._init_from_y(ctypes.byref(self.state), self._p(y), xb))

    @property
    def z(self) -> np.ndarray:
        """The state ``z`` (nz values: with a latched accommodation gate, the latches follow the observer's)."""
        return np.frombuffer(bytes(self.state), dtype=self.dtype, count=self.nz).astype(float)

    @property
    def gate(self) -> np.ndarray:
        """A latched accommodation gate's latches: the gates the last step applied (empty without latches; the
        memories of a remembering gate follow them in :attr:`z`)."""
        return self.z[self.nbar : self.nbar + (self.lf if self.latched else 0)]

    def step(self, y) -> tuple[int, np.ndarray, np.ndarray, np.ndarray]:
        yy = np.ascontiguousarray(y, dtype=self.dtype)
        u = np.zeros(self.m, dtype=self.dtype)
        xb = np.zeros(self.nbar, dtype=self.dtype)
        yc = np.zeros(self.p, dtype=self.dtype)
        rc = self._step(ctypes.byref(self.state), self._p(yy), self._p(u), self._p(xb), self._p(yc))
        return int(rc), u.astype(float), xb.astype(float), yc.astype(float)


def closed_loop_compare(
    design: Design,
    cstep: CStep,
    sample_time: float,
    steps: int,
    *,
    plant,
    fault=None,
    boundary_layer=None,
    start_from_y: bool = False,
):
    """Euler closed loop of the nonlinear plant driven by the CasADi step; the C step gets the same y.

    One sample per Euler step: the plant is integrated with the step ``sample_time`` the controller runs at.

    ``plant``: the nonlinear plant the design is for. ``start_from_y``: the plant starts at the
    design's nominal x0 and both observers start as ``fte simulate`` does, z0 = xbar0 - H y0 (the C
    through ``init_from_y``); otherwise the plant starts at its own x0 and both observers at z = 0. Returns a dict of the largest absolute differences (z, u, xbarhat, yc) over the run, plus
    the trajectories. ``fault(t, u) -> f`` gives the fault signal (default none).
    """
    F = plant.drift_function()
    fn = step_function(design, sample_time, boundary_layer=boundary_layer)
    n, m, ld, lf = plant.n, plant.m, plant.ld, plant.lf
    C, Df = np.asarray(design.C), np.asarray(design.Df)
    if start_from_y:
        x = design.xbar0[:n].copy()
        y0 = C @ x + (0.0 if fault is None else Df @ np.asarray(fault(0.0, np.zeros(m)), float))
        rc = cstep.init_from_y(y0)
        if rc != 0:
            raise CodegenError(f"the C init_from_y returned {rc} on a finite measurement")
        # both steps continue from the C's z0 (equal to xbar0 - H y0 up to round-off): at this start the
        # residual y - Cbar xbarhat is zero up to round-off, and sgn of a round-off would differ otherwise
        z = cstep.z
        if np.max(np.abs(z[: design.nbar] - (design.xbar0 - np.asarray(design.H) @ y0))) > 1e-12 * max(
            1.0, np.max(np.abs(z))
        ):
            raise CodegenError("the C init_from_y does not give z0 = xbar0 - H y0")
    else:
        x = np.asarray(plant.x0, float).copy()
        z = np.zeros(design.nz)
        cstep.init(z)
    err = {"z": 0.0, "u": 0.0, "xbarhat": 0.0, "yc": 0.0}
    traj = {"y": [], "u": [], "fhat": []}
    u_prev = np.zeros(m)
    for k in range(steps):
        t = k * sample_time
        f = np.zeros(lf) if fault is None else np.asarray(fault(t, u_prev), float)
        y = C @ x + Df @ f
        zn, u, xb, yc, _ = (np.asarray(v).ravel() for v in fn(z, y))
        rc, uc, xbc, ycc = cstep.step(y)
        if rc != 0:
            raise CodegenError(f"the C step returned {rc} at sample {k} on a finite measurement")
        err["z"] = max(err["z"], float(np.max(np.abs(cstep.z - zn))))
        err["u"] = max(err["u"], float(np.max(np.abs(uc - u))))
        err["xbarhat"] = max(err["xbarhat"], float(np.max(np.abs(xbc - xb))))
        err["yc"] = max(err["yc"], float(np.max(np.abs(ycc - yc))))
        traj["y"].append(y)
        traj["u"].append(u)
        traj["fhat"].append(xb[n + lf :])
        x = x + sample_time * np.asarray(F(x, u, np.zeros(ld), f)).ravel()
        z = zn
        u_prev = u
    return err, {k: np.array(v) for k, v in traj.items()}
