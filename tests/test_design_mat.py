"""Issue #20: the design document as a MAT file, every contract matrix under its name."""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner
from scipy.io import loadmat, savemat

from fte_casadi.cli import main

MATS = ("C", "Df", "H", "T", "X", "P", "Kf", "Pbar", "N", "Ls")
PER_RULE = ("K", "Q", "L1", "L2", "R")


@pytest.mark.parametrize("plant", ["manipulator", "three-tank"])
def test_mat_holds_every_contract_matrix_of_the_json(plant, real_designs, tmp_path):
    d = real_designs[plant]
    d.save(tmp_path / "d.json")
    d.save_mat(tmp_path / "d.mat")
    doc = json.loads((tmp_path / "d.json").read_text())
    v = loadmat(tmp_path / "d.mat")
    for k in MATS:
        np.testing.assert_array_equal(v[k], np.asarray(doc[k], dtype=float).reshape(v[k].shape), err_msg=k)
        assert v[k].shape[0] == len(doc[k])
    r = doc["dims"]["r"]
    for k in PER_RULE:
        assert v[k].shape == (r, 1), k
        for i in range(r):
            np.testing.assert_array_equal(v[k][i, 0], np.asarray(doc[k][i], dtype=float), err_msg=f"{k}[{i}]")
    assert v["local_models"].shape == (r, 1)
    for i in range(r):
        for k in ("A", "B", "Bd", "Bf", "W"):
            np.testing.assert_array_equal(
                v["local_models"][i, 0][k][0, 0], np.asarray(doc["local_models"][i][k])
            )
    assert float(v["theta"][0, 0]) == doc["theta"]
    lmi = v["checks"]["lmi_max_eig"][0, 0]
    for k in ("45", "46", "55", "64"):
        assert float(lmi[f"lmi_{k}"][0, 0][0, 0]) == doc["checks"]["lmi_max_eig"][k]
    assert float(v["params"]["gamma"][0, 0][0, 0]) == doc["params"]["gamma"]


@pytest.mark.slow
def test_cli_writes_mat_and_keeps_a_foreign_one(tmp_path):
    f = tmp_path / "design.mat"
    r = CliRunner().invoke(main, ["design", "manipulator", "-o", str(f)])
    assert r.exit_code == 0, r.output
    assert loadmat(f)["H"].shape == (8, 3)
    r = CliRunner().invoke(main, ["design", "manipulator", "-o", str(f)])  # its own earlier file: replaced
    assert r.exit_code == 0, r.output
    foreign = tmp_path / "user.mat"
    savemat(foreign, {"data": np.arange(3.0)})
    before = foreign.read_bytes()
    r = CliRunner().invoke(main, ["design", "manipulator", "-o", str(foreign)])
    assert r.exit_code != 0 and "was not written by fte" in " ".join(r.output.split())
    assert foreign.read_bytes() == before
