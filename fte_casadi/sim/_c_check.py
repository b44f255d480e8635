"""The generated C against the simulation: one simulated path replayed through the compiled step.

``fte simulate`` runs the step in its compiled engine; the generated C is the same step written out by CasADi's
code generator. :func:`check_c` simulates one path of a scenario (the faulty run with tolerant control, which the
C always applies) at the C's sample time, every sample kept, and compiles the C. It checks the start a
deployment makes, ``init_from_y`` of the first measurement, against the simulation's ``z_0 = xbar0 - H y_0``
(equal up to rounding). It then starts the C with ``init`` at the simulation's own ``z_0``, bit for bit (a
rounding apart, ``sgn(s)`` of an ``s`` near 0 could differ), and feeds it the measurements the simulated plant
produced, sample by sample. Where the C returns what the simulation applied (``u``), estimated (``xbarhat``)
and read (``yc``), the C in that loop is the simulation's loop: the plant sees the same inputs. Where its step
refuses a measurement (a return code, the state held), the C would not do what the simulation shows from there.
"""

from __future__ import annotations

import dataclasses
import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..codegen import CStep, compile_shared, find_compiler
from ..design import Design
from ..errors import CodegenError

__all__ = []  # internal: `fte codegen --check` (docs/embedded-c.md)

#: the largest difference allowed, relative to the signal's largest magnitude on the path, for C in double
#: (measured: 0 on the built-ins and six plants of ours, docs/embedded-c.md)
TOLERANCE = 1e-9
#: compiled as the simulation's engine rounds (docs/simulation.md): every operation on its own, no fused
#: multiply-adds (a compiler that fuses them, as clang may, rounds differently: a build of your own may differ
#: from the simulation by that rounding)
CHECK_FLAGS = ("-ffp-contract=off",)
#: at most this many samples are replayed (a longer scenario is cut there: the recorded path's memory)
MAX_SAMPLES = 200_000
#: the signals compared, with their names in the report
SIGNALS = (("u", "u"), ("xbarhat", "xbarhat"), ("yc", "yc"))
_REASONS = {
    1: "a measurement holding a NaN or an infinity",
    2: "an error reported by the generated maths",
    3: "a measurement outside the range it accepts",
    4: "its new state or u would not be finite",
    -1: "a NULL pointer",
}


@dataclass(frozen=True)
class Replay:
    """What :func:`check_c` found. ``diff`` and ``scale`` per signal: the largest ``|C - simulation|`` and the
    largest ``|simulation|`` over the samples compared; ``refused``: ``(sample, return code)`` of the first
    sample the C refused, else None; ``tolerance``: relative, None for C in float (reported, not judged);
    ``start``: the largest ``|z_0|`` difference between the C's ``init_from_y`` and the simulation's start, and
    ``start_scale`` the largest ``|z_0|``; ``cut``: what was left out of the scenario (empty: nothing)."""

    scenario: str
    seed: int
    sample_time: float
    samples: int
    total: int
    real: str
    diff: dict
    scale: dict
    refused: tuple[int, int] | None
    tolerance: float | None
    detail: str = ""
    start: float = 0.0
    start_scale: float = 0.0
    cut: str = ""
    fmu: str = ""
    fmu_diff: float | None = None

    def relative(self, key: str) -> float:
        return self.diff[key] / self.scale[key] if self.scale[key] > 0 else self.diff[key]

    @property
    def start_relative(self) -> float:
        return self.start / max(1.0, self.start_scale)

    @property
    def fmu_ok(self) -> bool:
        """The FMU returns what the C returns (to :data:`TOLERANCE` of the largest signal; in float, without an error),
        or was not checked."""
        tol, d = self.tolerance, self.fmu_diff
        if d is None:
            return True
        return math.isfinite(d) and (tol is None or d <= tol * max(1.0, *self.scale.values()))

    def _fmu_text(self) -> str:
        if self.fmu or self.fmu_diff is None:  # not checked, or failed with its own words
            return self.fmu
        does = "returns" if self.fmu_ok else "does NOT return"
        return (
            f"; the FMU, fed the same through FMPy, {does} what the C started by init_from_y returns (largest "
            f"difference {self.fmu_diff:.3g})"
        )

    @property
    def ok(self) -> bool:
        if self.refused is not None:
            return False
        if not self.fmu_ok:
            return False
        if self.tolerance is None:
            return True
        return self.start_relative <= self.tolerance and all(
            self.relative(k) <= self.tolerance for k, _ in SIGNALS
        )

    def render(self) -> str:
        where = (f"one simulated path of scenario {self.scenario!r} (seed {self.seed}, the faulty run with tolerant "
                 f"control, {self.total} samples at Ts = {self.sample_time:g}{self.cut})")  # fmt: skip
        diffs = ", ".join(f"{name} {self.diff[k]:.3g} (of {self.scale[k]:.3g})" for k, name in SIGNALS)
        start = (f"init_from_y of the first measurement starts it {self.start:.3g} from the simulation's start (of "
                 f"{self.start_scale:.3g})")  # fmt: skip
        if self.refused is not None:
            k, rc = self.refused
            return (f"the C does not do what the simulation did: fed the measurements of {where}, its step returned "
                    f"{rc} at sample {k} (t = {k * self.sample_time:.6g}): {self.detail or _REASONS.get(rc, 'refused')}; "
                    f"from there it holds its state while the simulation's step runs on (up to there the largest "
                    f"differences: {diffs}; {start})")  # fmt: skip
        head = f"fed the measurements of {where}, the C returns the simulation's u, xbarhat and yc"
        if self.tolerance is None:
            return (f"{head} up to float's rounding, which the sliding term's sign amplifies: largest differences "
                    f"{diffs}; {start} (C in float: reported, not judged; in double they are held to {TOLERANCE:g} "
                    f"of each signal's largest magnitude){self._fmu_text()}")  # fmt: skip
        verdict = "within" if self.ok else "NOT within"
        return (f"{head}, and {start}: {verdict} {self.tolerance:g} of each one's largest magnitude (largest "
                f"differences {diffs}){self._fmu_text()}")  # fmt: skip


def check_c(design: Design, plant, scenario, src_dir, *, sample_time: float, real: str = "double",
            seed: int = 0, fmu=None) -> Replay:  # fmt: skip
    """Replay one simulated path of ``scenario`` (``seed``) through the C in ``src_dir`` (module docstring).

    Needs a C compiler (:class:`~fte_casadi.errors.CodegenError` naming what to install otherwise); compiles with
    the strict flags and :data:`CHECK_FLAGS`. The path is simulated at ``sample_time``, the C's, in the exact mode,
    over the whole samples of the horizon and at most :data:`MAX_SAMPLES` of them (the report says what a cut
    leaves out). With ``fmu`` (the FMU written beside the C), the FMU is fed the same measurements through FMPy
    and must return what the C started by ``init_from_y`` returns, as the FMU starts (:func:`_fmu_replay`)."""
    from ._c_range import accepted_measurements
    from ._engine import simulate
    from ._options import SimulateOptions

    scenario, cut = _horizon(scenario, sample_time)
    opts = SimulateOptions(dt=sample_time, record_every=1, record_all=True, progress=False, detect=False)
    run = simulate(design, plant, scenario, paths=1, seed=seed, options=opts).run("ftc")
    sim = {k: np.asarray(getattr(run, k))[0] for k, _ in SIGNALS}
    y = np.asarray(run.y)[0]
    z0 = first_observer_state(design, plant, scenario, dt=sample_time, seed=seed)
    lo, hi = accepted_measurements(design, sample_time)
    with tempfile.TemporaryDirectory(prefix="fte_check_") as tmp:
        lib = compile_shared(src_dir, Path(tmp) / "libstep.so", extra_flags=CHECK_FLAGS)
        got = _replay(design, CStep(lib, design, real), z0, y, sim, scenario=scenario, seed=seed,
                      sample_time=sample_time, real=real, cut=cut, accepted=(lo, hi))  # fmt: skip
        if fmu is None or got.refused is not None:
            return got
        text, worst = _fmu_replay(fmu, CStep(lib, design, real), y, sample_time)
        return dataclasses.replace(got, fmu=text, fmu_diff=worst)


def _fmu_replay(path, cstep, y, sample_time: float) -> tuple[str, float | None]:
    """The FMU at ``path`` (FMPy), fed ``y`` step by step (``fmi2SetReal`` of y_k, ``fmi2DoStep`` at t_k, its
    outputs u, xbarhat, yc read), against ``cstep`` started by ``init_from_y`` as the FMU starts: the report's
    sentence and the largest difference (None where FMPy is missing: reported, not judged)."""
    try:
        import fmpy
        from fmpy.fmi2 import FMU2Slave
    except ImportError:
        return "; the FMU was not checked: FMPy is not installed (pip install fmpy, or the [fmi] extra)", None
    md = fmpy.read_model_description(str(path))
    ins = [v.valueReference for v in md.modelVariables if v.causality == "input"]
    outs = [v.valueReference for v in md.modelVariables if v.causality == "output"]
    worst = 0.0
    with tempfile.TemporaryDirectory(prefix="fte_check_fmu_") as tmp:
        slave = FMU2Slave(guid=md.guid, unzipDirectory=fmpy.extract(str(path), unzipdir=tmp),
                          modelIdentifier=md.coSimulation.modelIdentifier, instanceName="check")  # fmt: skip
        slave.instantiate()
        try:
            slave.setupExperiment(startTime=0.0)
            slave.enterInitializationMode()
            slave.exitInitializationMode()
            if cstep.init_from_y(y[0]) != 0:
                return "; the FMU was not checked: the C's init_from_y refused the first measurement", None
            for k in range(len(y)):
                rc, u, xb, yc = cstep.step(y[k])
                if rc != 0:
                    break
                try:
                    slave.setReal(ins, [float(v) for v in y[k]])
                    slave.doStep(currentCommunicationPoint=k * sample_time, communicationStepSize=sample_time)
                    got = np.asarray(slave.getReal(outs[: len(u) + len(xb) + len(yc)]))
                except Exception as exc:  # noqa: BLE001 - FMPy raises its own on an FMU's error status
                    why = " ".join(str(exc).split()) or type(exc).__name__
                    return f"; the FMU does NOT do what the C does: at sample {k} (t = {k * sample_time:.6g}) {why}", (
                        math.inf)  # fmt: skip
                want = np.concatenate([u, xb, yc])
                worst = max(worst, float(np.max(np.abs(got - want))) if want.size else 0.0)
            slave.terminate()
        finally:
            slave.freeInstance()
    return "", worst


def first_observer_state(design, plant, scenario, *, dt: float, seed: int, path: int = 0, run: str = "ftc"):
    """``z_0`` of one path's run as :func:`simulate` (default scales) starts it (:meth:`Prepared.initial_states`,
    the same numbers bit for bit): for a replay of the path through the generated C (``fte codegen --check``)."""
    from ._engine import Prepared, _scales
    from ._result import RUNS

    steps = max(1, int(round(float(scenario.T) / dt)))
    prep = Prepared(design, plant, scenario, dt, steps, _scales(None, scenario))
    lay = prep.lay
    o = RUNS.index(run) * lay.run_state + plant.n
    return prep.initial_states(np.array([path]), seed)[0, o : o + lay.nbar]


def _horizon(scenario, sample_time: float):
    """``scenario`` over whole samples of ``sample_time``, at most :data:`MAX_SAMPLES`; and what that leaves out."""
    T = float(scenario.T)
    steps = min(math.floor(T / sample_time * (1 + 1e-12)), MAX_SAMPLES - 1)
    end = steps * sample_time
    if end >= T * (1 - 1e-12):
        return scenario, ""
    short = scenario.until(end)
    gone = [f"{fp.fault} [{fp.start:g}, {fp.stop:g})" for fp in scenario.faults if fp.start >= end]
    cut = f"; the scenario cut at t = {end:g} of {T:g}"
    cut += f" (fault windows left out: {', '.join(gone)})" if gone else ""
    return short, cut


def _replay(design, cstep, z0, y, sim, *, scenario, seed, sample_time, real, cut="", accepted=None) -> Replay:
    diff = dict.fromkeys(sim, 0.0)
    scale = {k: float(np.max(np.abs(v))) if v.size else 0.0 for k, v in sim.items()}
    nbar = int(design.dims.nbar)
    refused, detail, start = None, "", 0.0
    rc = cstep.init_from_y(y[0])  # the start a deployment makes
    if rc != 0:
        refused, detail = (
            (0, rc),
            "its init_from_y refused the first measurement: " + _why(design, y[0], rc, accepted),
        )
    else:
        start = float(np.max(np.abs(cstep.z[:nbar] - z0)))
        rc = cstep.init(z0)  # the simulation's own start, bit for bit
        if rc != 0:
            refused, detail = (0, rc), "its init refused the simulation's start z0 (outside Z_MIN .. Z_MAX)"
    if refused is None:
        for k in range(len(y)):
            rc, *got = cstep.step(y[k])
            if rc != 0:
                refused, detail = (k, rc), _why(design, y[k], rc, accepted)
                break
            for key, value in zip(sim, got):
                d = float(np.max(np.abs(value - sim[key][k]))) if value.size else 0.0
                diff[key] = max(diff[key], d if math.isfinite(d) else math.inf)
    samples = len(y) if refused is None else refused[0]
    tol = TOLERANCE if real == "double" else None
    return Replay(scenario.name, int(seed), float(sample_time), samples, len(y), real, diff, scale, refused, tol,
                  detail, start, float(np.max(np.abs(z0))) if len(z0) else 0.0, cut)  # fmt: skip


def _why(design: Design, y, rc: int, accepted) -> str:
    """The measurement the C refused, named where it is out of its range (``accepted``: the C's ``(lo, hi)``)."""
    if rc != 3 or accepted is None:
        return _REASONS.get(rc, f"return code {rc}")
    lo, hi = accepted
    names = list(design.names.get("outputs") or [f"y{k + 1}" for k in range(len(y))])
    out = [f"{names[k]} = {y[k]:.6g} outside [{lo[k]:.6g}, {hi[k]:.6g}]" for k in range(len(y))
           if not lo[k] <= y[k] <= hi[k]]  # fmt: skip
    hint = ("; the range is C x over the plant's region, widened (docs/embedded-c.md): keep the plant in its region, "
            "or widen the region (b.region) to where it runs and design again")  # fmt: skip
    return _REASONS[3] + (": " + ", ".join(out) if out else "") + hint


def require_compiler() -> None:
    """``--check`` compiles the C: a clear error, before any work, where no compiler is found."""
    if find_compiler() is None:
        raise CodegenError(
            "--check compiles the C: no C compiler found (looked for $CC, cc, gcc, clang on PATH); install one, "
            "e.g. `apt-get install gcc`, or set CC, or leave out --check"
        )


def require_same_sliding(design: Design, boundary_layer) -> None:
    """Refuse a ``--boundary-layer`` other than the design's own: the simulation runs the design's sliding term,
    and the C would differ from it by design."""
    own = design.params.boundary_layer
    if boundary_layer is not None and boundary_layer != own:
        runs = "sgn(s)" if own is None else f"the design's sat(s / {own:g})"
        raise CodegenError(
            f"--check compares the C with fte simulate's step, which runs {runs}; with --boundary-layer "
            f"{boundary_layer:g} the C runs sat(s / {boundary_layer:g}) and differs from it by design: check without "
            "--boundary-layer"
        )
