"""`fte derive`: the contract's document, file plants, and clear errors without tracebacks."""

import json
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
from tolerances import PAPER_A, PAPER_A_TANK, ROUNDOFF

from fte_casadi.cli import main

EXAMPLES = __import__("pathlib").Path(__file__).resolve().parents[1] / "examples"


def fte(*args, cwd=None):
    # the checkout under test first on the path, also when cwd is elsewhere (an installed copy may differ)
    root = str(EXAMPLES.parent)
    env = {
        **os.environ,
        "PYTHONPATH": os.pathsep.join([root, os.environ.get("PYTHONPATH", "")]).rstrip(os.pathsep),
    }
    return subprocess.run(
        [sys.executable, "-m", "fte_casadi", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        timeout=300,
        env=env,
    )


@pytest.fixture(scope="module")
def manip_doc():
    p = fte("derive", "manipulator", "--json")
    assert p.returncode == 0, p.stderr
    return json.loads(p.stdout)


def test_derive_document_manipulator(manip_doc):
    d = manip_doc
    assert d["plant"] == "manipulator" and d["rules"] == 2
    assert set(d["local_models"][0]) >= {"A", "B", "Bd", "Bf", "W"}
    assert d["premises"][0]["min"] == pytest.approx(-0.217234, abs=1e-3)
    assert d["premises"][0]["max"] == pytest.approx(1.0, abs=1e-3)
    assert np.array(d["local_models"][0]["A"])[3, 2] == pytest.approx(-22.83, abs=PAPER_A)
    assert np.array(d["local_models"][1]["A"])[3, 2] == pytest.approx(-18.77, abs=PAPER_A)
    assert d["fidelity"]["max_abs_error"] <= ROUNDOFF and d["fidelity"]["samples"] > 0


@pytest.mark.slow
def test_derive_document_three_tank():
    p = fte("derive", "three-tank", "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert d["rules"] == 3
    assert np.array(d["local_models"][1]["A"])[1, 1] == pytest.approx(-0.0289, abs=PAPER_A_TANK)
    assert d["fidelity"]["max_abs_error"] > 0


@pytest.mark.slow
def test_derive_table_and_example_file_plant():
    p = fte("derive", str(EXAMPLES / "pendulum_plant.py") + ":pendulum")
    assert p.returncode == 0, p.stderr
    assert "rule 2:" in p.stdout and "fidelity" in p.stdout and "sin(theta)/theta" in p.stdout


def _bad(tmp_path, args, needle):
    """A real process: a non-zero exit, the message on stderr, no traceback."""
    p = fte(*args, cwd=tmp_path)
    assert p.returncode != 0
    assert "Traceback" not in p.stderr
    assert needle in p.stderr.replace("\n", " "), p.stderr
    return p


def _refused(args, needle):
    """The same in process (CliRunner, the working directory set by the caller): the command ended by its own exit
    status, not by an exception it let through, and said ``needle``."""
    from click.testing import CliRunner

    r = CliRunner().invoke(main, args)
    assert r.exit_code not in (0, None) and (r.exception is None or isinstance(r.exception, SystemExit)), (
        r.exception
    )
    assert "Traceback" not in r.output and needle in r.output.replace("\n", " "), r.output


@pytest.mark.slow
def test_errors_are_clear(tmp_path, monkeypatch):
    """Each bad plant gives a non-zero exit and its message, never a traceback: once as a process (status 2), the
    others in process (a process each took 2 s of imports)."""
    assert _bad(tmp_path, ["derive", "manipulatr"], "unknown plant 'manipulatr'").returncode == 2
    monkeypatch.chdir(tmp_path)
    _refused(["derive", "missing.py:f"], "does not exist")
    (tmp_path / "syn.py").write_text("def f(:\n    pass\n")
    _refused(["derive", "syn.py:f"], "syntax error at line 1")
    (tmp_path / "boom.py").write_text("def f():\n    raise RuntimeError('no coefficients')\n")
    _refused(["derive", "boom.py:f"], "raised RuntimeError: no coefficients")
    (tmp_path / "notplant.py").write_text("def f():\n    return 42\n")
    _refused(["derive", "notplant.py:f"], "not a Plant")
    _refused(["derive", "notplant.py:g"], "has no function 'g'")
    (tmp_path / "dims.py").write_text(
        textwrap.dedent(
            """
            from fte_casadi import PlantBuilder
            def f():
                b = PlantBuilder("d")
                x1, x2 = b.states("x1", "x2")
                (u,) = b.inputs("u")
                (fa,) = b.faults("fa")
                b.drift([x2 + u + fa])
                b.outputs([x1])
                return b.build()
            """
        )
    )
    _refused(["derive", "dims.py:f"], "expected 2 instead of 1")
    (tmp_path / "unb.py").write_text(
        textwrap.dedent(
            """
            import casadi as ca
            from fte_casadi import PlantBuilder
            def f():
                b = PlantBuilder("d")
                (x,) = b.states("x")
                (u,) = b.inputs("u")
                (fa,) = b.faults("fa")
                m = b.premise("m", ca.exp(x))
                b.drift([-m * x + u + fa])
                b.outputs([x])
                return b.build()
            """
        )
    )
    _refused(["derive", "unb.py:f"], "no bounds")


@pytest.mark.slow
def test_click_runner_in_process(tmp_path):
    from click.testing import CliRunner

    r = CliRunner().invoke(main, ["derive", "manipulator"])
    assert r.exit_code == 0 and "[-0.217234, 1]" in r.output


PLANT_AUTO = __import__("pathlib").Path(__file__).resolve().parent / "plant_auto.py"


@pytest.mark.slow
def test_derive_finds_the_premises_of_the_plain_manipulator(manip_doc):
    """`fte derive` on (82) as printed: the premise it chose, its bounds, the rules, and that it was automatic."""
    p = fte("derive", f"{PLANT_AUTO}:manipulator_plain", "--json")
    assert p.returncode == 0, p.stderr
    d = json.loads(p.stdout)
    assert set(d) >= set(manip_doc) - {"method"} and d["rules"] == 2 and d["premises_found_automatically"]
    assert [(q["expr"], q["min"], q["max"]) for q in d["premises"]] == [
        (q["expr"], q["min"], q["max"]) for q in manip_doc["premises"]
    ]
    np.testing.assert_allclose(np.array([lm["A"] for lm in d["local_models"]]),
                               np.array([lm["A"] for lm in manip_doc["local_models"]]), rtol=0, atol=1e-12)  # fmt: skip
    assert d["fidelity"]["max_abs_error"] <= ROUNDOFF
    t = fte("derive", f"{PLANT_AUTO}:manipulator_plain")
    assert t.returncode == 0, t.stderr
    assert "2 rules by sector (premises found automatically)" in t.stdout
    assert "z1 = sin(theta_l)/theta_l: [-0.217234, 1]" in t.stdout
    assert "1 premise, 2 rules" in t.stdout and "z1 schedules A[w_l, theta_l], W[w_l, theta_l]" in t.stdout


@pytest.mark.slow
def test_derive_linear_plant_is_one_rule():
    p = fte("derive", f"{PLANT_AUTO}:linear")
    assert p.returncode == 0, p.stderr
    assert "1 rules by linear (one rule)" in p.stdout and "no nonlinear term in the states" in p.stdout
    assert "rule 2:" not in p.stdout


@pytest.mark.slow
def test_derive_refuses_an_unbounded_term_by_name(tmp_path):
    (tmp_path / "pole.py").write_text(
        textwrap.dedent(
            """
            from fte_casadi import PlantBuilder
            def f():
                b = PlantBuilder("pole")
                x1, x2 = b.states("x1", "x2")
                (u,) = b.inputs("u")
                (fa,) = b.faults("fa")
                b.drift([x2, -x1 - 1 / x1 + u + fa])
                b.outputs([x1, x2])
                b.region(x1=(-1, 1), x2=(-1, 1))
                return b.build()
            """
        )
    )
    p = _bad(tmp_path, ["derive", "pole.py:f"], "drift row 'x2': the term -(1/x1) is unbounded on the region")
    assert p.returncode != 0 and "Traceback" not in p.stderr
