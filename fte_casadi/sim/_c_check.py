"""The generated C against the simulation: one simulated path replayed through the compiled step.

``fte simulate`` runs the step in its compiled engine; the generated C is the same step written out by CasADi's
code generator. :func:`check_c` simulates one path of a scenario (the faulty run with tolerant control, which the
C always applies) at the C's sample time, every sample kept, compiles the C, starts it where the simulation
started its observer (``init`` with the simulation's ``z_0 = xbar0 - H y_0``, bit for bit: ``init_from_y``
computes the same up to rounding, and a rounding of ``sgn(s)``'s argument near 0 would differ) and feeds it the
measurements the simulated plant produced, sample by sample. Where the C returns what the simulation applied (``u``), estimated (``xbarhat``) and
read (``yc``), the C in that loop is the simulation's loop: the plant sees the same inputs. Where its step
refuses a measurement (a return code, the state held), the C would not do what the simulation shows from there.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..codegen import CStep, compile_shared, find_compiler, output_range
from ..design import Design
from ..errors import CodegenError

__all__ = []  # internal: `fte codegen --check` (docs/embedded-c.md)

#: the largest difference allowed, relative to the signal's largest magnitude on the path, for C in double
#: (measured: 0 to 3e-14 on the built-ins and the levitation; the two differ in the order of a few operations)
TOLERANCE = 1e-9
#: compiled as the simulation's engine rounds (docs/simulation.md): every operation on its own, no fused
#: multiply-adds (a compiler that fuses them, as clang may, rounds differently: a build of your own may differ
#: from the simulation by that rounding)
CHECK_FLAGS = ("-ffp-contract=off",)
#: at most this many samples are replayed (a longer scenario is cut there: the recorded path's memory)
MAX_SAMPLES = 200_000
#: the signals compared, with their names in the report
SIGNALS = (("u", "u"), ("xbarhat", "xbarhat"), ("yc", "yc"))
_REASONS = {1: "a measurement holding a NaN or an infinity", 3: "a measurement outside the range it accepts",
            -1: "a NULL pointer"}  # fmt: skip


@dataclass(frozen=True)
class Replay:
    """What :func:`check_c` found. ``diff`` and ``scale`` per signal: the largest ``|C - simulation|`` and the
    largest ``|simulation|`` over the samples compared; ``refused``: ``(sample, return code)`` of the first
    sample the C refused, else None; ``tolerance``: relative, None for C in float (reported, not judged)."""

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

    def relative(self, key: str) -> float:
        return self.diff[key] / self.scale[key] if self.scale[key] > 0 else self.diff[key]

    @property
    def ok(self) -> bool:
        if self.refused is not None:
            return False
        return self.tolerance is None or all(self.relative(k) <= self.tolerance for k, _ in SIGNALS)

    def render(self) -> str:
        cut = (
            ""
            if self.total == self.samples or self.refused
            else f" (the first {self.samples} of {self.total})"
        )
        where = (f"one simulated path of scenario {self.scenario!r} (seed {self.seed}, the faulty run with tolerant "
                 f"control, {self.total} samples at Ts = {self.sample_time:g}{cut})")  # fmt: skip
        diffs = ", ".join(f"{name} {self.diff[k]:.3g} (of {self.scale[k]:.3g})" for k, name in SIGNALS)
        if self.refused is not None:
            k, rc = self.refused
            return (f"the C does not do what the simulation did: fed the measurements of {where}, its step returned "
                    f"{rc} at sample {k} (t = {k * self.sample_time:.6g}): {self.detail or _REASONS.get(rc, 'refused')}; "
                    f"from there it holds its state while the simulation's step runs on (up to there the largest "
                    f"differences: {diffs})")  # fmt: skip
        head = f"fed the measurements of {where}, the C returns the simulation's u, xbarhat and yc"
        if self.tolerance is None:
            return (f"{head} up to float's rounding, which the sliding term's sign amplifies: largest differences "
                    f"{diffs} (C in float: reported, not judged; in double they are held to {TOLERANCE:g} of each "
                    "signal's largest magnitude)")  # fmt: skip
        verdict = "within" if self.ok else "NOT within"
        return f"{head} {verdict} {self.tolerance:g} of each signal's largest magnitude: largest differences {diffs}"


def check_c(design: Design, plant, scenario, src_dir, *, sample_time: float, real: str = "double",
            seed: int = 0) -> Replay:  # fmt: skip
    """Replay one simulated path of ``scenario`` (``seed``) through the C in ``src_dir`` (module docstring).

    Needs a C compiler (:class:`~fte_casadi.errors.CodegenError` naming what to install otherwise); compiles with
    the strict flags and :data:`CHECK_FLAGS`. The path is simulated at ``sample_time``, the C's, in the exact mode,
    and cut after :data:`MAX_SAMPLES` samples."""
    from ._engine import first_observer_state, simulate
    from ._options import SimulateOptions

    steps = int(round(float(scenario.T) / sample_time))
    if steps > MAX_SAMPLES:
        scenario = scenario.until(MAX_SAMPLES * sample_time)
    opts = SimulateOptions(dt=sample_time, record_every=1, record_paths=1, progress=False, detect=False)
    run = simulate(design, plant, scenario, paths=1, seed=seed, options=opts).run("ftc")
    sim = {k: np.asarray(getattr(run, k))[0] for k, _ in SIGNALS}
    y = np.asarray(run.y)[0]
    z0 = first_observer_state(design, plant, scenario, dt=sample_time, seed=seed)
    with tempfile.TemporaryDirectory(prefix="fte_check_") as tmp:
        lib = compile_shared(src_dir, Path(tmp) / "libstep.so", extra_flags=CHECK_FLAGS)
        cstep = CStep(lib, design, real)
        return _replay(design, cstep, z0, y, sim, scenario=scenario, seed=seed, sample_time=sample_time,
                       real=real, total=max(steps, len(y)))  # fmt: skip


def _replay(design, cstep, z0, y, sim, *, scenario, seed, sample_time, real, total) -> Replay:
    diff = dict.fromkeys(sim, 0.0)
    scale = {k: float(np.max(np.abs(v))) if v.size else 0.0 for k, v in sim.items()}
    refused, detail = None, ""
    rc = cstep.init(z0)
    if rc != 0:
        refused, detail = (0, rc), _why(design, y[0], rc, real, start=True)
    else:
        for k in range(len(y)):
            rc, *got = cstep.step(y[k])
            if rc != 0:
                refused, detail = (k, rc), _why(design, y[k], rc, real)
                break
            for key, value in zip(sim, got):
                d = float(np.max(np.abs(value - sim[key][k]))) if value.size else 0.0
                diff[key] = max(diff[key], d if math.isfinite(d) else math.inf)
    samples = len(y) if refused is None else refused[0]
    tol = TOLERANCE if real == "double" else None
    return Replay(scenario.name, int(seed), float(sample_time), samples, int(total), real, diff, scale, refused,
                  tol, detail)  # fmt: skip


def _why(design: Design, y, rc: int, real: str, start: bool = False) -> str:
    """The measurement the C refused, named where it is out of its range."""
    if start:
        return ("its init refused the simulation's start z0 (1: not finite, 3: outside Z_MIN .. Z_MAX, "
                "docs/embedded-c.md)")  # fmt: skip
    if rc != 3:
        return _REASONS.get(rc, f"return code {rc}")
    rng = output_range(design, real=real)
    names = list(design.names.get("outputs") or [f"y{k + 1}" for k in range(len(y))])
    out = [f"{names[k]} = {y[k]:.6g} outside [{rng['lo'][k]:.6g}, {rng['hi'][k]:.6g}]" for k in range(len(y))
           if not rng["lo"][k] <= y[k] <= rng["hi"][k]]  # fmt: skip
    hint = ("; the range is C x over the plant's region, widened (docs/embedded-c.md): keep the plant in its region, "
            "or widen the region (b.region) to where it runs and design again")  # fmt: skip
    return _REASONS[3] + (": " + ", ".join(out) if out else "") + hint


def require_check_target(real: str, boundary_layer) -> None:
    """Refuse what ``--check`` cannot do: compile without a compiler, compare a boundary layer (the simulation
    runs ``sgn(s)``)."""
    if find_compiler() is None:
        raise CodegenError(
            "--check compiles the C: no C compiler found (looked for $CC, cc, gcc, clang on PATH); install one, "
            "e.g. `apt-get install gcc`, or set CC, or leave out --check"
        )
    if boundary_layer is not None:
        raise CodegenError(
            "--check compares the C with fte simulate's step, which runs sgn(s); with --boundary-layer the C runs "
            "sat(s/PHI) and differs from it by design: check without --boundary-layer"
        )
    if real not in ("double", "float"):
        raise CodegenError(f"--real must be double or float; got {real!r}")
