"""The committed C of the built-in plants (generated/) is what the generator makes today.

Each ``generated/<plant>/`` holds ``design.json``, the design its code was made from; the code
is regenerated from it into a temporary folder and must be identical byte for byte (the output
is deterministic: no timestamps, constants printed with 17 significant digits). On a failure,
run ``python -c "from fte_casadi.codegen import regenerate_builtin; regenerate_builtin('generated')"``
(or ``fte codegen --builtin``) and commit the result.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from fte_casadi.codegen.generate import BUILTIN_DIRS, generate_c, output_files
from fte_casadi.design.record import Design

GENERATED = Path(__file__).resolve().parents[1] / "generated"


@pytest.mark.parametrize("plant", sorted(BUILTIN_DIRS))
def test_generated_code_is_fresh(plant, tmp_path):
    folder = GENERATED / BUILTIN_DIRS[plant]
    assert (folder / "design.json").is_file(), f"{folder} lacks design.json; regenerate the built-in code"
    design = Design.load(folder / "design.json")
    assert design.plant == plant
    generate_c(design, tmp_path)
    stale = [f for f in output_files(plant) if (folder / f).read_bytes() != (tmp_path / f).read_bytes()]
    assert not stale, (
        f"generated/{BUILTIN_DIRS[plant]}: {stale} differ from a fresh generation; regenerate them"
    )


def test_generation_is_deterministic(tmp_path):
    design = Design.load(GENERATED / "manipulator" / "design.json")
    a, b = tmp_path / "a", tmp_path / "b"
    generate_c(design, a, real="float")
    generate_c(design, b, real="float")
    for f in output_files("manipulator"):
        assert (a / f).read_bytes() == (b / f).read_bytes()


@pytest.mark.parametrize("plant", sorted(BUILTIN_DIRS))
def test_committed_design_is_todays_design(plant, real_designs):
    """generated/<plant>/design.json is what `fte design <plant>` gives today (to SDP reproducibility)."""
    from tolerances import SDP_REPRO_REL

    committed = Design.load(GENERATED / BUILTIN_DIRS[plant] / "design.json")
    fresh = real_designs[plant]
    assert committed.variant == fresh.variant == "conditioned"
    for key in ("H", "T", "Kf", "N", "Ls", "u_ref"):
        a, b = np.asarray(getattr(committed, key)), np.asarray(getattr(fresh, key))
        assert np.max(np.abs(a - b), initial=0) <= SDP_REPRO_REL * max(1.0, np.max(np.abs(b), initial=0)), key
    for key in ("K", "L1", "L2", "R"):
        for a, b in zip(getattr(committed, key), getattr(fresh, key)):
            assert np.max(np.abs(a - b)) <= SDP_REPRO_REL * max(1.0, np.max(np.abs(b))), key
