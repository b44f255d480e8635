"""Record the measurements of examples/embedded/measurements.txt (run from the repository root).

A short Euler closed loop of the nonlinear manipulator, driven by the in-process CasADi step of
the design in generated/manipulator/design.json at the generated sample time, with a 40 % loss
of actuator effectiveness from t = 0.3 s. The plant starts at the design's nominal x0 and the
observer from the first measurement, as ``fte simulate`` and ``fte_manipulator_init_from_y`` do. Deterministic (no noise), so the file can be
regenerated bit for bit: ``python examples/embedded/make_measurements.py``.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from fte_casadi.codegen._generate import default_sample_time
from fte_casadi.design._record import Design
from fte_casadi.plants import manipulator
from fte_casadi.step import step_function

ROOT = Path(__file__).resolve().parents[2]
HORIZON_S = 0.6
FAULT_START_S = 0.3


def record(design: Design, horizon: float = HORIZON_S) -> tuple[float, np.ndarray]:
    """Sample time and measurements (rows of y) of the closed loop."""
    plant = manipulator()
    F = plant.drift_function()
    sample_time = default_sample_time(design)
    fn = step_function(design, sample_time)
    x = design.xbar0[: plant.n].copy()
    z = design.observer_start(design.C @ x)
    u = np.zeros(plant.m)
    ys = []
    for k in range(int(round(horizon / sample_time))):
        f = np.array([-0.4 * u[0] if k * sample_time >= FAULT_START_S else 0.0, 0.0])
        y = design.C @ x + design.Df @ f
        ys.append(y)
        zn, un, *_ = (np.asarray(v).ravel() for v in fn(z, y))
        x = x + sample_time * np.asarray(F(x, un, np.zeros(plant.ld), f)).ravel()
        z, u = zn, un
    return sample_time, np.array(ys)


def main() -> None:
    design = Design.load(ROOT / "generated" / "manipulator" / "design.json")
    sample_time, ys = record(design)
    lines = [
        f"# manipulator measurements theta_m w_m theta_l, Ts = {sample_time!r} s, actuator fault from {FAULT_START_S} s"
    ]
    lines += [" ".join(f"{v:.12g}" for v in y) for y in ys]
    (Path(__file__).parent / "measurements.txt").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
