"""A design document is data: tampered documents are refused with exit 2 naming what fails, a document's
code is never run, and the user's mistakes get exit 2 with one paragraph, never exit 3."""

import json
import shutil
from pathlib import Path

import casadi as ca
import numpy as np
import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.design import Design
from fte_casadi.trust import check_loaded

ROOT = Path(__file__).resolve().parents[1]
MANIP = ROOT / "generated" / "manipulator" / "design.json"
TANK = ROOT / "generated" / "three_tank" / "design.json"


def run(*args):
    r = CliRunner().invoke(main, [str(a) for a in args])
    return r.exit_code, " ".join(r.output.split())  # the messages are wrapped at 100 columns


def tampered(tmp_path, src=MANIP, name="d.json", **edits):
    doc = json.loads(src.read_text())
    for k, fn in edits.items():
        doc[k] = fn(doc[k]) if callable(fn) else fn
    out = tmp_path / name
    out.write_text(json.dumps(doc).replace('"__1e400__"', "1e400"))  # a literal beyond a double's range
    return out


def neg(v):
    return [(-np.asarray(M)).tolist() for M in v]


def test_committed_documents_recertify_quickly():
    for f in (MANIP, TANK):
        t = check_loaded(Design.load(f))
        assert t.design.certified and t.plant is not None and not t.notes


@pytest.mark.parametrize("cmd", ["simulate", "codegen"])
def test_negated_K_is_refused_naming_the_LMI(tmp_path, cmd):
    f = tampered(tmp_path, K=neg)
    extra = ["--out", tmp_path / "c"] if cmd == "codegen" else ["--paths", "1"]
    code, out = run(cmd, f, *extra)
    assert code == 2, out
    assert "LMI (45) recomputes to +" in out and "closed loop A_1 + B_1 K_1" in out
    assert "Traceback" not in out and not (tmp_path / "c").exists()


def test_negated_L1_is_refused_naming_the_observer(tmp_path):
    code, out = run("codegen", tampered(tmp_path, L1=neg), "--out", tmp_path / "c")
    assert code == 2, out
    assert "the observer matrix R_1" in out and "eigenvalue with real" in out and "R_1 is not" in out


@pytest.mark.slow
def test_certified_false_and_missing(tmp_path):
    code, out = run("codegen", tampered(tmp_path, certified=False), "--out", tmp_path / "c")
    assert code == 2 and '"certified": false' in out, out
    doc = json.loads(MANIP.read_text())
    del doc["certified"]
    d = Design.from_dict(doc)
    assert d.certified is False  # missing is not true ...
    assert check_loaded(d).design.certified is True  # ... it is re-checked


def test_allow_uncertified_proceeds_and_says_so(tmp_path):
    f = tampered(tmp_path, K=neg)
    code, out = run("codegen", f, "--out", tmp_path / "c", "--allow-uncertified")
    assert code == 0, out
    assert "WARNING: NOT CERTIFIED" in out
    header = (tmp_path / "c" / "fte_manipulator.h").read_text()
    assert "NOT CERTIFIED" in header
    good = (ROOT / "generated" / "manipulator" / "fte_manipulator.h").read_text()
    assert "NOT CERTIFIED" not in good


@pytest.mark.parametrize(
    "key, value, named",
    [
        ("theta", "__1e400__", "'theta'"),
        ("theta", -1, "'theta'"),
        ("theta", "nan", "'theta'"),
        ("params", lambda p: {**p, "epsilon": "inf"}, "'params.epsilon'"),
        ("params", lambda p: {**p, "gamma": "nan"}, "'params.gamma'"),
        ("params", lambda p: {**p, "delta": -1e-3}, "'params.delta'"),
        ("params", lambda p: {**p, "sigma": True}, "'params.sigma'"),
        ("dims", lambda p: {**p, "n": True}, "'dims.n'"),
        ("K", lambda K: [np.asarray(M)[:, :2].tolist() for M in K], "'K[0]'"),
        ("Pbar", lambda M: [[True] * len(M)] * len(M), "'Pbar'"),
        ("u_ref", ["inf"], "'u_ref'"),
        ("schema", 99, "schema 99"),
    ],
)
def test_bad_numbers_and_shapes_are_named(tmp_path, key, value, named):
    f = tampered(tmp_path, **{key: value})
    code, out = run("codegen", f, "--out", tmp_path / "c", "--plant", "manipulator")
    assert code == 2, out
    assert named in out and "Traceback" not in out and "internal error" not in out


@pytest.mark.parametrize(
    "tape",
    [
        lambda t: {**t, "ops": [[48, [0], [0]]] + t["ops"]},  # OP_CALL: not an arithmetic operation
        lambda t: {**t, "ops": [[1, [0], [7777, 0]]] + t["ops"]},  # reads a slot never written
        lambda t: {**t, "outputs": [3]},  # three memberships for two rules
        "garbage",
    ],
)
def test_corrupt_scheduling_tape_is_refused(tmp_path, tape):
    f = tampered(tmp_path, scheduling_ops=tape, plant_spec="mine.py:plant")  # no plant: the tape is read
    code, out = run("codegen", f, "--out", tmp_path / "c")
    assert code == 2, out
    assert "'scheduling_ops'" in out and "internal error" not in out


@pytest.mark.slow
def test_edited_plant_file_is_refused(tmp_path):
    src = (ROOT / "examples" / "pendulum_plain.py").read_text()
    plant = tmp_path / "pend.py"
    plant.write_text(src)
    doc = tmp_path / "pend.json"
    code, out = run("design", f"{plant}:pendulum", "-o", doc)
    assert code == 0, out
    assert run("codegen", doc, "--out", tmp_path / "c0", "--plant", f"{plant}:pendulum")[0] == 0
    plant.write_text(src.replace("b_u = 9.81, 0.8, 2.0", "b_u = 9.81, 0.8, -2.0"))
    code, out = run("codegen", doc, "--out", tmp_path / "c", "--plant", f"{plant}:pendulum")
    assert code == 2, out
    assert "the plant's equations" in out and "differ from those the design was made for" in out
    assert "the drift" in out
    # without --plant the document's own file is not imported: codegen works from the document's data ...
    code, out = run("codegen", doc, "--out", tmp_path / "c1")
    assert code == 0 and "does not import" in out, out
    # ... and simulate, which needs the true plant, asks for it
    code, out = run("simulate", doc, "--paths", "1")
    assert code == 2 and "--plant" in out, out


def test_a_documents_plant_spec_is_never_imported(tmp_path, monkeypatch):
    marker = tmp_path / "ran"
    evil = tmp_path / "evil.py"
    evil.write_text(
        f"open({str(marker)!r}, 'w').write('x')\ndef plant():\n    open({str(marker)!r}, 'w').write('y')\n"
    )
    for spec in (f"{evil}:plant", "os:getpid"):
        f = tampered(tmp_path, plant_spec=spec, name="e.json")
        for cmd in (["simulate", f, "--paths", "1"], ["sweep", f, "--vary", "fault_scale=1"]):
            code, out = run(*cmd)
            assert code == 2 and spec in out and "--plant" in out, out
        code, out = run("codegen", f, "--out", tmp_path / "c")  # from the document's own data, said so
        assert code == 0 and "does not import" in out, out
        assert not marker.exists()


def test_scheduling_is_never_deserialised(tmp_path, monkeypatch):
    calls = []
    monkeypatch.setattr(ca.Function, "deserialize", lambda *a: calls.append(a))
    f = tampered(tmp_path, scheduling="not a casadi function at all", plant_spec="mine.py:plant")
    code, out = run("codegen", f, "--out", tmp_path / "c")
    assert code == 0, out
    # an old document (no scheduling_ops) with a plant fte may not import: refused, nothing deserialised
    doc = json.loads(f.read_text())
    del doc["scheduling_ops"]
    f.write_text(json.dumps(doc))
    code, out = run("codegen", f, "--out", tmp_path / "c2")
    assert code == 2 and "does not deserialise" in out and "--plant" in out, out
    assert calls == []


def test_old_document_without_schema_still_loads(tmp_path):
    doc = json.loads(MANIP.read_text())
    for k in ("schema", "plant_hash", "scheduling_ops"):
        del doc[k]
    f = tmp_path / "old.json"
    f.write_text(json.dumps(doc))
    code, out = run("codegen", f, "--out", tmp_path / "c")  # a built-in plant: the map is rebuilt from it
    assert code == 0, out
    for name in ("fte_manipulator_casadi.c", "fte_manipulator.h"):
        assert (tmp_path / "c" / name).read_bytes() == (MANIP.parent / name).read_bytes()


def test_deep_json_and_user_mistakes_exit_2(tmp_path):
    deep = tmp_path / "deep.json"
    deep.write_text("[" * 100000 + "]" * 100000)
    code, out = run("codegen", deep, "--out", tmp_path / "c")
    assert code == 2 and "nests" in out, out
    code, out = run("simulate", TANK, "--seed", "99999999999999999999999", "--paths", "1")
    assert code == 2 and "--seed" in out, out
    code, out = run("simulate", TANK, "--paths", "100000000000")
    assert code == 2 and "memory" in out and "GB" in out, out


@pytest.mark.slow
def test_unicode_plant_name_works(tmp_path):
    src = (ROOT / "examples" / "pendulum_plain.py").read_text()
    plant = tmp_path / "pend.py"
    plant.write_text(src.replace('PlantBuilder("pendulum-plain")', 'PlantBuilder("pendül")'))
    code, out = run("derive", f"{plant}:pendulum")
    assert code == 0, out
    assert "pendül" in out


def test_copy_of_generated_folder_unchanged(tmp_path):
    """The tests above never write into generated/."""
    shutil.copy(MANIP, tmp_path / "m.json")
    assert Design.load(tmp_path / "m.json").certified


@pytest.mark.parametrize(
    "edit, expect",
    [
        (("b_u = 9.81, 0.8, 2.0", "b_u = 9.81, float('inf'), 2.0"), "give every coefficient a finite value"),
        (("b_u = 9.81, 0.8, 2.0", "b_u = 9.81, 0.8, 1e12"), "coefficients span a factor"),
    ],
)
def test_bad_plant_coefficients_exit_2_with_a_true_message(tmp_path, edit, expect):
    src = (ROOT / "examples" / "pendulum_plain.py").read_text()
    assert edit[0] in src
    plant = tmp_path / "pend.py"
    plant.write_text(src.replace(*edit))
    code, out = run("design", f"{plant}:pendulum")
    assert code == 2, out
    assert expect in out and "internal error" not in out
