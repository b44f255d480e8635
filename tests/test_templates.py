"""The hand-written C lives in template files that ship with the package and are what the generator fills."""

from __future__ import annotations

import fnmatch
import re
import zipfile
from importlib.resources import files
from pathlib import Path

import pytest

from fte_casadi.codegen import _template as template
from fte_casadi.codegen._generate import c_name, generate_c, output_files
from fte_casadi.design import Design
from fte_casadi.errors import CodegenError

ROOT = Path(__file__).resolve().parents[1]
DESIGN = ROOT / "generated" / "manipulator" / "design.json"
PLACEHOLDER = re.compile(r"\$\{(\w+)\}")


def test_every_template_file_is_listed_and_ships_as_package_data():
    folder = files("fte_casadi.codegen").joinpath("templates")
    on_disk = sorted(p.name for p in folder.iterdir() if p.is_file())
    assert on_disk == sorted(template.TEMPLATES.values())
    tomllib = pytest.importorskip("tomllib")  # Python 3.11+
    cfg = tomllib.loads((ROOT / "pyproject.toml").read_text())
    patterns = cfg["tool"]["setuptools"]["package-data"]["fte_casadi.codegen"]
    for name in on_disk:
        assert any(fnmatch.fnmatch(f"templates/{name}", p) for p in patterns), (name, patterns)


def test_templates_hold_c_not_python_escapes():
    for name in template.TEMPLATES.values():
        text = template.read(name)
        assert text.isascii() and "\r" not in text and text.endswith("\n"), name
        assert '"""' not in text and "\\\\n" not in text, name  # no Python literal carried over


def _literals(name: str) -> list[str]:
    """The template's text between placeholders (the parts copied as they are)."""
    return [s for s in PLACEHOLDER.split(template.read(name))[::2] if s]


def _in_order(parts: list[str], text: str) -> bool:
    at = 0
    for s in parts:
        at = text.find(s, at)
        if at < 0:
            return False
        at += len(s)
    return True


def test_generated_wrapper_and_readme_come_from_the_template_files(tmp_path):
    design = Design.load(DESIGN)
    generate_c(design, tmp_path)
    fh, fc, _, _, readme = output_files(design.plant)
    for key, out in (("header", fh), ("source", fc), ("readme", readme)):
        text = (tmp_path / out).read_text()
        assert "${" not in text
        assert _in_order(_literals(template.TEMPLATES[key]), text), key


def test_fill_names_a_missing_placeholder():
    with pytest.raises(CodegenError, match=r"fte_NAME\.h\.in.*needs a value for \$\{\w+\}"):
        template.fill(template.TEMPLATES["header"], {"name": "x"})
    with pytest.raises(CodegenError, match="is missing"):
        template.read("no_such_template.c.in")


def test_fmu_sources_come_from_the_template_files(tmp_path):
    from fte_casadi.codegen import _build as build
    from fte_casadi.codegen._fmu import FMI2_HEADER_NAME, generate_fmu, model_identifier

    if build.find_compiler() is None:
        pytest.skip("no C compiler (cc, gcc, clang) on PATH")
    design = Design.load(DESIGN)
    fmu = generate_fmu(design, tmp_path)
    mid = model_identifier(design.plant)
    with zipfile.ZipFile(fmu) as z:
        wrapper = z.read(f"sources/{mid}_fmi2.c").decode()
        header = z.read(f"sources/{FMI2_HEADER_NAME}").decode()
    assert header == template.read(template.TEMPLATES["fmi2_header"])
    assert "${" not in wrapper and f'#include "fte_{c_name(design.plant)}.h"' in wrapper
    assert _in_order(_literals(template.TEMPLATES["fmu_wrapper"]), wrapper)
