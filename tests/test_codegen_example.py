"""examples/embedded: build main.c with the committed generated/manipulator code and run it."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest
from tolerances import C_DOUBLE

from fte_casadi.codegen import _build as build
from fte_casadi.codegen import default_sample_time
from fte_casadi.design import Design
from fte_casadi.step import step_function

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "examples" / "embedded"
GEN = ROOT / "generated" / "manipulator"


def _measurements() -> np.ndarray:
    rows = [
        line.split()
        for line in (EXAMPLE / "measurements.txt").read_text().splitlines()
        if not line.startswith("#")
    ]
    return np.array(rows, dtype=float)


@pytest.mark.slow
@pytest.mark.skipif(build.find_compiler() is None, reason="no C compiler (cc, gcc, clang) on PATH")
def test_example_runs_and_matches_casadi(tmp_path):
    exe = build.compile_program(GEN, EXAMPLE / "main.c", tmp_path / "fte_example")
    out = build.run_program(exe, str(EXAMPLE / "measurements.txt"))
    got = np.array([line.split() for line in out.splitlines() if not line.startswith("#")], dtype=float)
    ys = _measurements()
    assert got.shape == (len(ys), 4)
    design = Design.load(GEN / "design.json")
    fn = step_function(design, default_sample_time(design))
    z = design.observer_start(ys[0])  # main.c starts with init_from_y on the first measurement
    for k, y in enumerate(ys):
        z, u, xb, *_ = (np.asarray(v).ravel() for v in fn(z, y))
        assert got[k, 0] == k
        assert np.max(np.abs(got[k, 1:] - np.concatenate([u, xb[6:]]))) <= C_DOUBLE * max(
            1.0, np.max(np.abs(u))
        )
    assert got[-1, 2] < -0.05  # the actuator fault (40 % loss from 1 s) is estimated


def test_measurements_file_is_fresh():
    """measurements.txt is what make_measurements.py records with the committed design."""
    spec = importlib.util.spec_from_file_location("make_measurements", EXAMPLE / "make_measurements.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    ts, ys = mod.record(Design.load(GEN / "design.json"))
    # the file holds 12 significant digits
    assert np.allclose(ys, _measurements(), rtol=1e-11, atol=1e-12), (
        "regenerate with python examples/embedded/make_measurements.py"
    )
