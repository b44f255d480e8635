"""A design document is data, round 2: every number its step uses is checked on load (Kf, H, N, u_ref, the
limits, the region, x0, ts_max), names cannot write C, and what a document or an option cannot mean is
refused with exit 2 and a message naming it."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fte_casadi.cli import main
from fte_casadi.design import Design, augment, identity_failures
from fte_casadi.trust import check_loaded

ROOT = Path(__file__).resolve().parents[1]
MANIP = ROOT / "generated" / "manipulator" / "design.json"
TANK = ROOT / "generated" / "three_tank" / "design.json"


def run(*args):
    r = CliRunner().invoke(main, [str(a) for a in args])
    return r.exit_code, " ".join(r.output.split())  # the messages are wrapped at 100 columns


def write(tmp_path, doc, name="d.json") -> Path:
    out = tmp_path / name
    out.write_text(json.dumps(doc))
    return out


def scaled(v, c):
    return (np.asarray(v, float) * c).tolist()


def with_H(doc: dict, c: float) -> dict:
    """``doc`` with H scaled by ``c`` and T, R, L2, Ls (and N) rebuilt to match: every identity the certificate
    checks holds, but T Bd_i = 0 does not."""
    d = Design.from_dict(doc)
    aug = augment(d.local_models, d.C, d.Df)
    H = np.asarray(d.H) * c
    T = np.eye(aug.nbar) - H @ aug.Cbar
    R = [T @ aug.Abar[i] - np.asarray(d.L1[i]) @ aug.Cbar for i in range(aug.r)]
    N = aug.Js.T @ T.T @ np.asarray(d.Pbar) @ np.linalg.pinv(aug.Cbar)
    return {**doc, "H": H.tolist(), "T": T.tolist(), "R": [M.tolist() for M in R],
            "L2": [(M @ H).tolist() for M in R], "Ls": (T @ aug.Js).tolist(), "N": N.tolist()}  # fmt: skip


@pytest.fixture(scope="module")
def manip() -> dict:
    return json.loads(MANIP.read_text())


def test_the_committed_documents_satisfy_every_identity():
    for f in (MANIP, TANK):
        assert identity_failures(Design.load(f)) == []


@pytest.mark.parametrize(
    "edit, named",
    [
        (lambda d: {**d, "Kf": scaled(d["Kf"], -1)}, "Kf is not -pinv(B_1) Bf_1"),
        (lambda d: {**d, "Kf": scaled(d["Kf"], 10)}, "Kf is not -pinv(B_1) Bf_1"),
        (lambda d: with_H(d, 1.01), "T Bd_1 is not 0"),
        (lambda d: with_H(d, 1.01), "H is not the unknown-input gain (17)"),
        (lambda d: {**d, "N": scaled(d["N"], 3)}, "N is not J1^T T^T Pbar Cbar^+"),
        (lambda d: {**d, "checks": {**d["checks"], "ts_max": 1.0}}, "checks.ts_max is 1 but the observer"),
    ],
)
def test_a_number_the_step_uses_is_checked_on_load(tmp_path, manip, edit, named):
    f = write(tmp_path, edit(manip))
    code, out = run("codegen", f, "--out", tmp_path / "c", "--plant", "manipulator")
    assert code == 2, out
    assert named in out and "not certified at its own numbers" in out, out
    assert not (tmp_path / "c").exists()


def test_the_decoupling_of_a_tampered_H_is_measured(manip):
    d = Design.from_dict(with_H(manip, 1.01))
    why = [w for w in identity_failures(d) if "T Bd_1" in w][0]
    top = float(why.split("= ")[1].split(" ")[0])
    assert 1e-4 < top < 1.0  # the issue measured 0.005 against 1e-16 for the untouched design
    aug = augment(d.local_models, d.C, d.Df)
    good = Design.from_dict(manip)
    assert np.max(np.abs(np.asarray(good.T) @ aug.Bdbar[0])) < 1e-12


def test_a_dropped_kf_rules_is_refused(tmp_path):
    import sys

    sys.path.insert(0, str(ROOT / "tests"))
    import plant_kf_rules

    from fte_casadi.design import design
    from fte_casadi.ts import structure

    d = design(structure(plant_kf_rules.plant()), sample_time=1e-3)
    assert d.Kf_rules is not None and identity_failures(d) == []
    doc = d.to_dict()
    del doc["Kf_rules"]
    assert any("no Kf_rules" in w for w in identity_failures(Design.from_dict(doc)))
    doc = d.to_dict()
    doc["Kf_rules"][1] = scaled(doc["Kf_rules"][1], 2)
    assert any("Kf_rules[1] is not -pinv(B_2) Bf_2" in w for w in identity_failures(Design.from_dict(doc)))


@pytest.mark.parametrize(
    "src, edit, named",
    [
        (MANIP, lambda d: {**d, "u_ref": [0.7]}, "its u_ref is [0.7], not the plant's reference"),
        (
            TANK,
            lambda d: {**d, "u_ref": scaled(d["u_ref"], 1.01)},
            "not the input holding the plant at x_ref",
        ),
        (
            MANIP,
            lambda d: {**d, "input_limits": [[-1e6, 1e6]]},
            "its input_limits are [[-1000000. 1000000.]], the plant's none",
        ),  # fmt: skip
        (TANK, lambda d: {**d, "input_limits": None}, "its input_limits are none, the plant's [[ 0. 100.]"),
        (TANK, lambda d: {**d, "input_limits": [[-1e6, 1e6], [0, 100]]}, "its input_limits are"),
        (
            MANIP,
            lambda d: {**d, "x0": [9.0, 0, 0, 0]},
            "its x0 = [9.0, 0.0, 0.0, 0.0] lies outside the plant's "
            "region (theta_m = 9 not in [-6.28319, 6.28319])",
        ),  # fmt: skip
        (
            MANIP,
            lambda d: {**d, "checks": {**d["checks"], "region": {"lo": [-60] * 4, "hi": [60] * 4}}},
            "its checks.region is",
        ),  # fmt: skip
    ],
)
def test_numbers_are_checked_against_the_plant(tmp_path, src, edit, named):
    plant = "manipulator" if src == MANIP else "three-tank"
    for drop_hash in (False, True):  # a document without plant_hash is caught as well
        doc = edit(json.loads(src.read_text()))
        if drop_hash:
            doc = {k: v for k, v in doc.items() if k != "plant_hash"}
        code, out = run("codegen", write(tmp_path, doc), "--out", tmp_path / "c", "--plant", plant)
        assert code == 2, out
        assert named in out and f"does not match its plant ({plant})" in out, out


def test_a_document_without_plant_hash_says_so(tmp_path, manip):
    doc = {k: v for k, v in manip.items() if k != "plant_hash"}
    t = check_loaded(Design.from_dict(doc, "d.json"))
    assert any("has no plant_hash" in n and "compared through its T-S model" in n for n in t.notes)
    t = check_loaded(Design.from_dict({**doc, "plant_spec": "mine.py:plant"}, "d.json"))
    assert any("unchecked against any plant" in n for n in t.notes)


# -- names are data ---------------------------------------------------------------------------------------

INJECTION = "y1 */ static inline int f(void) { return 42; } /*"


@pytest.mark.parametrize("plant", [None, "manipulator"])
def test_a_name_that_would_write_c_is_refused_on_load(tmp_path, manip, plant):
    names = {**manip["names"], "outputs": [INJECTION, "y2", "y3"]}
    f = write(tmp_path, {**manip, "names": names})
    code, out = run("codegen", f, "--out", tmp_path / "c", *(["--plant", plant] if plant else []), "--fmu")
    assert code == 2, out
    assert "'names.outputs[0]' holds a C comment" in out and "a document is data" in out, out
    assert not (tmp_path / "c").exists()


@pytest.mark.parametrize(
    "key, value, why",
    [
        ("plant", "x\ny", "holds a line break"),
        ("names", {"states": ["a", "b", "c", "d\u202e"]}, "holds a control or format character (U+202E)"),
        ("names", {"state_units": ["rad", "rad/s", "rad", "x" * 201]}, "is 201 characters long"),
        ("names", {"faults": ["fa"]}, "must be a list of 2 names (dims.lf)"),
        ("names", {"time_unit": "s */"}, "holds a C comment terminator"),
        ("names", {"outputs": ["a??/", "b", "c"]}, "holds '??'"),
    ],
)
def test_names_and_units_are_plain_labels(tmp_path, manip, key, value, why):
    doc = {**manip, key: {**manip["names"], **value} if key == "names" else value}
    code, out = run("codegen", write(tmp_path, doc), "--out", tmp_path / "c")
    assert code == 2 and why in out, out


def test_with_plant_the_names_are_the_plants(tmp_path, manip):
    names = {
        **manip["names"],
        "outputs": ["bogus_a", "bogus_b", "bogus_c"],
        "states": ["q1", "q2", "q3", "q4"],
    }
    f = write(tmp_path, {**manip, "names": names})
    code, out = run("codegen", f, "--out", tmp_path / "c", "--plant", "manipulator")
    assert code == 0, out
    header = (tmp_path / "c" / "fte_manipulator.h").read_text()
    assert "bogus" not in header and "q1" not in header
    assert header == (MANIP.parent / "fte_manipulator.h").read_text()


def test_the_builder_refuses_names_that_are_not_labels():
    from fte_casadi import PlantBuilder
    from fte_casadi.errors import PlantError

    with pytest.raises(PlantError, match=r"plant name 'p \*/ int x; /\*' holds a C comment opener"):
        PlantBuilder("p */ int x; /*")
    b = PlantBuilder("p")
    with pytest.raises(PlantError, match="state unit 'rad\\\\n' holds a line break"):
        b.states("x1", units=["rad\n"])
    with pytest.raises(PlantError, match="time unit 's`' holds a backquote"):
        b.time_unit("s`")
    with pytest.raises(PlantError, match="not a valid identifier"):
        b.inputs("u */")


#: the number of a set of generated files (a hash of their text, comments included): not text of the document
SET_ID = re.compile(r"0x[0-9a-f]{8}UL")


def code_only(src: str) -> str:
    """C source without its comments, string literals and character constants (each kept as an empty
    ``""``/``''``), and with the set's number as ``SET``: what a compiler reads as code, less the hash."""
    out, k, n = [], 0, len(src)
    while k < n:
        two = src[k : k + 2]
        if two == "/*":
            end = src.find("*/", k + 2)
            assert end >= 0, "an unterminated comment"
            k = end + 2
            out.append(" ")
        elif two == "//":
            end = src.find("\n", k)
            k = n if end < 0 else end
        elif src[k] in "\"'":
            q, k = src[k], k + 1
            while src[k] != q:
                assert src[k] != "\n", "a string literal runs past its line"
                k += 2 if src[k] == "\\" else 1
            k += 1
            out.append(q + q)
        else:
            out.append(src[k])
            k += 1
    return SET_ID.sub("SET", "".join(out))


def test_code_only_sees_through_comments_and_strings():
    assert code_only('a /* b */ c // d\ne "f\\"g" \'h\'') == "a   c \ne \"\" ''"
    with pytest.raises(AssertionError, match="unterminated"):
        code_only("x /* y")


@pytest.fixture(scope="module")
def fmu_baseline(tmp_path_factory):
    """The FMU's C sources of the manipulator's design under the plant name 'Zq9' and neutral names, comments
    and strings removed, the plant's C name replaced by '@'; and its README."""
    import zipfile

    from fte_casadi.codegen import generate_fmu

    d = Design.load(MANIP)
    import dataclasses

    base = dataclasses.replace(d, plant="Zq9")
    path = generate_fmu(base, tmp_path_factory.mktemp("base"))
    with zipfile.ZipFile(path) as z:
        code = {Path(n).name.replace("Zq9", "@"): code_only(z.read(n).decode()).replace("Zq9", "@").replace(
            "ZQ9", "@") for n in z.namelist() if n.startswith("sources/")}  # fmt: skip
        return d, code, z.read("documentation/README.md").decode()


@pytest.mark.slow
def test_random_names_compile_and_inject_nothing(fmu_baseline, tmp_path_factory):
    """Names with C, XML and Markdown metacharacters, given in code (not through a document's checks): the
    generated C, its header and the FMU compile under the strict flags, and with comments and string literals
    removed the C is the C of neutral names: no name is code."""
    import dataclasses
    import xml.etree.ElementTree as ET
    import zipfile

    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import strategies as st

    from fte_casadi.codegen import generate_fmu
    from fte_casadi.codegen._generate import c_name

    d, base, base_readme = fmu_baseline
    meta = st.sampled_from(["*/", "/*", "//", "\\", "\n", "\r\n", '"', "'", "<", ">", "&", "]]>", "?", "??/", "#",
                            "`", "%s", "\x00", "\x1b", "\u202e", "\u2028", "é", "θ", "${name}", "$$", "{", "}",
                            ";", INJECTION, "#include <stdio.h>", "*", "/", " "])  # fmt: skip
    label = st.lists(st.one_of(meta, st.text(max_size=4)), min_size=1, max_size=5).map("".join)

    # no shrinking: an example compiles for a second, and a failure prints the example found
    @settings(max_examples=12, deadline=None, phases=(Phase.explicit, Phase.reuse, Phase.generate),
              suppress_health_check=[HealthCheck.function_scoped_fixture])  # fmt: skip
    @given(
        plant=label, states=st.lists(label, min_size=4, max_size=4), inputs=st.lists(label, min_size=1, max_size=1),
        outputs=st.lists(label, min_size=3, max_size=3), faults=st.lists(label, min_size=2, max_size=2),
        units=st.lists(label, min_size=4, max_size=4), time_unit=label,
    )  # fmt: skip
    def check(plant, states, inputs, outputs, faults, units, time_unit):
        names = {"states": states, "inputs": inputs, "outputs": outputs, "faults": faults, "state_units": units,
                 "output_units": units[:3], "input_units": units[:1], "time_unit": time_unit}  # fmt: skip
        plant = "Zq9" + plant
        cn = c_name(plant)
        path = generate_fmu(dataclasses.replace(d, plant=plant, names=names), tmp_path_factory.mktemp("f"))
        with zipfile.ZipFile(path) as z:  # generate_fmu compiled every source under the strict flags
            ET.fromstring(z.read("modelDescription.xml"))
            got = {Path(n).name.replace(cn, "@"): code_only(z.read(n).decode()).replace(cn, "@").replace(
                cn.upper(), "@") for n in z.namelist() if n.startswith("sources/")}  # fmt: skip
            readme = z.read("documentation/README.md").decode()
        assert got == base
        for mark in ("\n", "`", r"\|", r"<(?!U\+[0-9A-F]{4,6}>)"):  # no line, code span, table cell or HTML
            assert len(re.findall(mark, readme)) == len(re.findall(mark, base_readme)), mark

    check()


# -- options honoured or refused --------------------------------------------------------------------------


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--gamma", "2"], "--explore searches gamma and sigma itself: --gamma cannot be given"),
        (["--sigma", "0.1", "--gamma", "2"], "--gamma and --sigma cannot be given"),
        (["--allow-uncertified"], "--explore writes only a certified design"),
    ],
)
def test_explore_refuses_what_it_cannot_honour(tmp_path, extra, named):
    code, out = run("design", "manipulator", "--explore", "--out", tmp_path / "f", *extra)
    assert code == 2 and named in out, out
    assert not (tmp_path / "f").exists()


@pytest.mark.slow
def test_explore_takes_the_options_of_a_design(tmp_path, monkeypatch):
    """One options record for a design and for --explore: kappa, alpha, the sample time and the plant as it was
    named reach the frontier's designs and its -o document (which then loads with the suggested --plant)."""
    import importlib

    design_pkg = importlib.import_module(
        "fte_casadi.design"
    )  # the package (fte_casadi.design is the function)
    real = design_pkg.explore
    seen = []

    def one_sigma(ts, options, **kw):  # the frontier at one sigma: the CLI's options are what is tested
        seen.append(options)
        return real(ts, options, sigmas=[0.1866], budget=None, progress=kw.get("progress"))

    monkeypatch.setattr(design_pkg, "explore", one_sigma)
    spec = f"{ROOT / 'examples' / 'pendulum_plain.py'}:pendulum"
    doc = tmp_path / "best.json"
    code, out = run("design", spec, "--explore", "--out", tmp_path / "f", "-o", doc, "--kappa", "5000",
                    "--sample-time", "0.002", "--gamma1", "0.1")  # fmt: skip
    assert code == 0, out
    (o,) = seen
    assert (o.kappa, o.sample_time, o.gamma1, o.plant_spec) == (5000.0, 0.002, 0.1, spec)
    d = Design.load(doc)
    assert d.plant_spec == spec and d.params.kappa == 5000.0 and d.observer.sample_time == 0.002
    code, out = run("codegen", doc, "--out", tmp_path / "c", "--plant", d.plant_spec)
    assert code == 0, out


@pytest.mark.parametrize(
    "extra, named",
    [
        (["--release", "0.7"], "--release is the hysteresis of --accommodate's gate"),
        (["--false-alarm-rate", "1", "--no-detection"], "--false-alarm-rate sets the detection thresholds"),
        (["--measurement-noise="], "--measurement-noise is empty"),
        (
            ["--measurement-noise", "0.1"],
            "--measurement-noise has 1 entries; the plant has 2 outputs (h1, h2)",
        ),
        (
            ["--measurement-noise", "1e308,0"],
            "1e+308 for output h1 exceeds the whole range the generated C "
            "accepts for it ([14, 26], width 12)",
        ),  # fmt: skip
        (
            ["--false-alarm-rate", "1e300"],
            "--false-alarm-rate 1e+300 asks for at least one false alarm per sample",
        ),
        (
            ["--accommodate", "--save-design", "X.npz", "--save", "X.npz"],
            "--save and --save-design name the same file",
        ),  # fmt: skip
    ],
)
def test_simulate_refuses_options_that_mean_nothing_before_the_work(tmp_path, monkeypatch, extra, named):
    import importlib

    sim = importlib.import_module("fte_casadi.sim")
    monkeypatch.setattr(sim, "simulate", lambda *a, **k: pytest.fail("the Monte Carlo ran"))
    monkeypatch.chdir(tmp_path)
    code, out = run("simulate", TANK, "--paths", "1", "--quiet", *extra)
    assert code == 2 and named in out, out
    assert list(tmp_path.iterdir()) == []


def test_a_result_that_is_not_finite_is_refused(tmp_path, monkeypatch):
    import importlib

    sim = importlib.import_module("fte_casadi.sim")
    real = sim.simulate

    def overflowed(*a, **k):
        res = real(*a, **k)
        res.metrics["state_rms_error"][1] = float("nan")
        return res

    monkeypatch.setattr(sim, "simulate", overflowed)
    code, out = run("simulate", TANK, "--paths", "1", "--quiet", "--json", "--no-detection")
    assert code == 2 and "the run's results are not finite (state_rms_error[1])" in out, out
    assert "NaN" not in out


@pytest.mark.parametrize("value", [1e308, 1e160])
def test_a_parameter_whose_square_overflows_is_refused(tmp_path, manip, value):
    doc = {**manip, "params": {**manip["params"], "gamma": value}}
    code, out = run("codegen", write(tmp_path, doc), "--out", tmp_path / "c")
    assert code == 2 and "'params.gamma' must be a finite number > 0 and <= 1e+100" in out, out
    code, out = run("design", "manipulator", "--gamma", str(value))
    assert code == 2 and "--gamma must be at most 1e+100" in out, out


# -- the smaller ways to lose work or read garbage ---------------------------------------------------------


def test_a_key_twice_is_refused(tmp_path):
    text = MANIP.read_text()
    f = tmp_path / "d.json"
    f.write_text(text.rstrip().rstrip("}") + ', "plant": "other"}')
    code, out = run("codegen", f, "--out", tmp_path / "c")
    assert code == 2 and "holds the key 'plant' twice in one JSON object" in out, out


def test_what_is_no_design_document_is_named(tmp_path):
    folder = tmp_path / "d.json"
    folder.mkdir()
    from fte_casadi.errors import DesignFileError

    with pytest.raises(DesignFileError, match="is a directory; give the design document itself"):
        Design.load(folder)
    for target in (folder, tmp_path):
        code, out = run("simulate", target, "--paths", "1")
        assert code == 2 and f"{target} is a directory; give a design document" in out, out
    mat = tmp_path / "d.mat"
    mat.write_bytes(b"MATLAB 5.0 MAT-file, written by scipy" + bytes(200))
    code, out = run("codegen", mat, "--out", tmp_path / "c")
    assert code == 2 and "is a MAT file" in out and "give the .json one" in out, out
    big = tmp_path / "big.json"
    with open(big, "wb") as fh:  # a sparse file: 65 MB that take no disk and must not be read
        fh.truncate(65 * 2**20)
    code, out = run("codegen", big, "--out", tmp_path / "c")
    assert code == 2 and "is 65 MB, more than the 64 MB a design document fte reads may be" in out, out


def test_an_output_in_a_missing_folder_is_refused_before_the_work(tmp_path, monkeypatch):
    import fte_casadi.cli._design as cli_design

    monkeypatch.setattr(cli_design, "_make_design", lambda *a, **k: pytest.fail("designed"))
    code, out = run("design", "manipulator", "-o", tmp_path / "no" / "d.json")
    assert code == 2 and f"the directory {tmp_path / 'no'} does not exist (checked before any work)" in out, (
        out
    )


def test_design_of_a_plant_instead_of_its_model_says_so():
    from fte_casadi import design
    from fte_casadi.errors import ParameterError
    from fte_casadi.plants import manipulator

    with pytest.raises(
        ParameterError, match=r"design\(\) takes the T-S model of a plant, not the plant itself"
    ):
        design(manipulator())


def test_names_in_the_mat_file_are_one_line_each(tmp_path):
    """A design given names in code (no document's checks on the way) writes them to MAT as plain text."""
    import dataclasses

    from scipy.io import loadmat

    d = Design.load(MANIP)
    names = {**d.names, "outputs": ["a\nb", "c\x00", "d\u202e"]}
    dataclasses.replace(d, plant="p\r\nq", names=names).save_mat(tmp_path / "d.mat")
    m = loadmat(tmp_path / "d.mat", simplify_cells=True)
    assert m["plant"] == "p<U+000D><U+000A>q"
    assert list(m["names"]["outputs"]) == ["a<U+000A>b", "c<U+0000>", "d<U+202E>"]
