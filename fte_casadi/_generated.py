"""The committed C of the built-in plants (``generated/``): made from their designs, kept fresh by a test.

``regenerate_builtin("generated")`` designs each built-in plant (the conditioned variant at its
scenario's sample time), writes ``design.json`` and generates the C from that very document, so
that the test can regenerate the C from the committed document and compare byte for byte. It sits
above codegen/ because it needs the built-in plants.
"""

from __future__ import annotations

import os
from pathlib import Path

from .codegen import BUILTIN_DIRS, file_mode, generate_c, prepare_dir
from .design import Design

__all__ = ["builtin_design", "regenerate_builtin"]


def builtin_design(plant_name: str) -> Design:
    """The design used for ``generated/``: the conditioned LMI design of the built-in plant for its scenario, with
    the gate ``fte design`` writes (:func:`fte_casadi.sim.protected`)."""
    from .design import DesignOptions
    from .design import design as lmi_design
    from .plants import BUILTIN, SCENARIOS
    from .sim import protected
    from .ts import derive

    sc = SCENARIOS[plant_name]()
    plant = BUILTIN[plant_name]()
    options = sc.design_options(DesignOptions(variant="conditioned", plant_spec=plant_name))
    return protected(lmi_design(derive(plant), options), plant, sc, paths=sc.paths, seed=0)


def regenerate_builtin(root: str | os.PathLike, names=None) -> dict[str, list[Path]]:
    """Regenerate ``root/manipulator``, ``root/three_tank`` and ``root/quadruple_tank`` (``root`` is ``generated/``).

    Each folder gets ``design.json`` (the design the code was made from, so that the code can
    be regenerated bit for bit) and the files of :func:`generate_c` with the default sample
    time and ``double``. ``names`` limits it to some plants (default: all).
    """
    out = {}
    for plant_name, sub in BUILTIN_DIRS.items():
        if names is not None and plant_name not in names:
            continue
        d = builtin_design(plant_name)
        folder = Path(root) / sub
        prepare_dir(folder)
        d.save(folder / "design.json")
        os.chmod(folder / "design.json", file_mode())
        out[plant_name] = [folder / "design.json", *generate_c(Design.load(folder / "design.json"), folder)]
    return out
