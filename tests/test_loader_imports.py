"""A plant file may import modules from its own folder (parameters apart from equations)."""

from __future__ import annotations

import json
import sys
import textwrap

from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.plants import load_plant, load_scenario

PLANT = """
import casadi as ca
from fte_casadi import PlantBuilder
from {params} import GAIN, LOSS  # a module beside this file


def plant():
    b = PlantBuilder("two_files")
    x1, x2 = b.states("x1", "x2")
    (u,) = b.inputs("u")
    (d,) = b.unknown_inputs("d")
    (fa,) = b.faults("fa", kind="actuator")
    b.drift([x2 + 0.1 * d, -x1 - 0.5 * x2 + GAIN * (u + fa) - 0.2 * d])
    b.diffusion([0.0, 0.01 * x2])
    b.outputs([x1, x2])
    b.region(x1=(-1.0, 1.0), x2=(-1.0, 1.0))
    return b.build()


def scenario():
    from fte_casadi.sim import LossOfEffectiveness, Scenario

    return Scenario(name="two_files", T=2.0, dt=1e-3, faults=(LossOfEffectiveness("fa", loss=LOSS, start=0.5, stop=1.5),))
"""


def _write(folder, gain, loss, params="params"):
    folder.mkdir()
    (folder / f"{params}.py").write_text(f"GAIN = {gain}\nLOSS = {loss}\n")
    (folder / "plant.py").write_text(textwrap.dedent(PLANT.format(params=params)))
    return folder / "plant.py"


def test_plant_file_imports_a_module_beside_it_and_leaves_sys_path_alone(tmp_path):
    path_before, modules_before = list(sys.path), set(sys.modules)
    a = _write(tmp_path / "a", gain=2.0, loss=0.3)
    b = _write(tmp_path / "b", gain=5.0, loss=0.6)  # a helper of the same name in another folder
    pa, pb = load_plant(f"{a}:plant"), load_plant(f"{b}:plant")
    assert sys.path == path_before
    assert "params" not in sys.modules and "params" not in modules_before
    # each plant got its own parameters: the input gain is the coefficient of u in the second drift row
    ga = float(pa.drift_function()([0, 0], [1.0], [0], [0])[1])
    gb = float(pb.drift_function()([0, 0], [1.0], [0], [0])[1])
    assert (ga, gb) == (2.0, 5.0)
    assert load_scenario(f"{b}:plant").faults[0].loss == 0.6
    assert sys.path == path_before


def test_cli_derives_a_two_file_plant(tmp_path):
    f = _write(tmp_path / "p", gain=2.0, loss=0.3, params="plant_params")
    r = CliRunner().invoke(main, ["derive", f"{f}:plant", "--json"])
    assert r.exit_code == 0, r.output
    doc = json.loads(r.stdout)
    assert doc["rules"] == 1 and doc["local_models"][0]["B"] == [[0.0], [2.0]]
