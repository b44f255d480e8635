"""The documentation: the MkDocs site builds with --strict (a broken link, a missing anchor or a
docstring the API reference cannot render fails), the README stays a front page whose links
resolve, and every citation of a documentation page in the code points at a page that exists."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = ROOT / "docs"


@pytest.mark.slow
def test_site_builds_strict(tmp_path):
    site = tmp_path / "site"
    proc = subprocess.run(
        [
            sys.executable,
            "-m",
            "mkdocs",
            "build",
            "--strict",
            "-f",
            str(ROOT / "mkdocs.yml"),
            "-d",
            str(site),
        ],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert proc.returncode == 0, f"mkdocs build --strict failed:\n{proc.stdout}\n{proc.stderr}"
    # the reference pages are there, and the API reference rendered the docstrings (not an empty page)
    for page in ("method", "interface", "api"):
        assert (site / page / "index.html").is_file(), page
    api = (site / "api" / "index.html").read_text()
    for name in ("fte_casadi.design.design", "fte_casadi.ts.derive", "fte_casadi.sim.simulate",
                 "fte_casadi.step.step_function", "fte_casadi.codegen.generate_c"):  # fmt: skip
        assert f'id="{name}"' in api, name


def _nav_pages() -> set[str]:
    return set(re.findall(r":\s*([\w./-]+\.md)\s*$", (ROOT / "mkdocs.yml").read_text(), re.M))


def test_nav_names_existing_pages():
    pages = _nav_pages()
    assert {"index.md", "method.md", "interface.md", "api.md"} <= pages
    assert all((DOCS / p).is_file() for p in pages), sorted(p for p in pages if not (DOCS / p).is_file())


def test_readme_is_a_front_page_whose_links_resolve():
    text = (ROOT / "README.md").read_text()
    assert len(text.splitlines()) <= 200
    assert "## Quickstart" in text
    links = re.findall(r"\]\(([^)#\s]+)(?:#[^)]*)?\)", text)
    local = [u for u in links if not re.match(r"[a-z]+:", u)]
    assert local, "the README links to its documentation pages"
    missing = [u for u in local if not (ROOT / u).exists()]
    assert not missing, f"README links to files that do not exist: {missing}"


def _sources():
    for top in ("fte_casadi", "tests", "generated", "examples", "docs"):
        for p in (ROOT / top).rglob("*"):
            if p.is_file() and p.suffix in (".py", ".c", ".h", ".md", ".txt"):
                yield p
    yield ROOT / "README.md"


def test_citations_resolve_inside_the_repository():
    """The code cites the project's own pages (docs/method.md, docs/interface.md, ...), never the
    notes outside the repository it was first written against."""
    outside = re.compile("SPEC" + r"\.md|CONTRACT" + r"\.md")
    cited = re.compile(r"docs/([\w-]+\.md)")
    bad, missing = [], []
    for p in _sources():
        text = p.read_text(errors="replace")
        if outside.search(text):
            bad.append(str(p.relative_to(ROOT)))
        missing += [
            f"{p.relative_to(ROOT)}: docs/{m}" for m in cited.findall(text) if not (DOCS / m).is_file()
        ]
    assert not bad, f"citations of files outside the repository: {bad}"
    assert not missing, f"citations of documentation pages that do not exist: {missing}"


# -- citations of the code: every file, module and name the docs (and the docstrings) cite exists -----------------
#: the folders a cited path may start with (a subpackage's folder: relative to fte_casadi/)
_FOLDERS = ("fte_casadi", "tests", "examples", "baselines", "docs", "generated", "tools", "design", "sim", "ts",
            "codegen", "model", "plot", "plants", "tune", "bench", "cli")  # fmt: skip
_PATH = re.compile(r"(?<![\w/.-])((?:" + "|".join(_FOLDERS) + r")/(?:[\w-]+/)*[\w-]+\.(?:py|md)|_\w+\.py)"
                   r"(?::\s*(\w+))?")  # fmt: skip
_DOTTED = re.compile(r"(?<![\w./])(fte_casadi(?:\.\w+)+)")
_FROM = re.compile(r"from (fte_casadi[\w.]*) import ([\w ,]+)")
#: names the docs cite that are gone on purpose: docs/names.md's names before 0.2.0
FORMER = {"fte_casadi.codegen.default_ts"}
#: placeholders written in place of a module's name
PLACEHOLDERS = {"_x.py", "_name.py", "tests/test_FILE.py"}


def _resolves(dotted: str) -> bool:
    """Is ``dotted`` a module of the package, or a name in one (``fte_casadi.design.core._certify.failed``)?"""
    import importlib

    parts = dotted.split(".")
    for k in range(len(parts), 0, -1):
        try:
            obj = importlib.import_module(".".join(parts[:k]))
        except ImportError:
            continue
        for a in parts[k:]:
            if not hasattr(obj, a):
                return False
            obj = getattr(obj, a)
        return True
    return False


def _defines(path: Path, name: str) -> bool:
    import ast

    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)) and node.name == name:
            return True
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == name for t in node.targets
        ):
            return True
    return False


def _cited_file(cited: str, name: str | None) -> str | None:
    """What is wrong with the citation of the file ``cited`` (and its ``name``), or None."""
    if cited in PLACEHOLDERS:
        return None
    if "/" in cited:
        hit = next((p for p in (ROOT / cited, ROOT / "fte_casadi" / cited) if p.exists()), None)
    else:  # a private module named alone, in a page that says where
        hit = next(iter((ROOT / "fte_casadi").rglob(cited)), None)
    if hit is None:
        return f"{cited} does not exist"
    if name and hit.suffix == ".py" and not _defines(hit, name):
        return f"{cited} defines no {name}"
    return None


def _doc_citations(text: str) -> list[str]:
    """What the page ``text`` cites that does not exist: files (``design/_recertify.py: certify``), modules and
    names (``fte_casadi.design.core._certify``), and names imported in its code blocks."""
    bad = []
    fenced = re.findall(r"```.*?```", text, re.S)
    inline = re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", text, flags=re.S))
    for span in inline:
        bad += [w for m in _PATH.finditer(span) if (w := _cited_file(m.group(1), m.group(2)))]
    for span in inline + fenced:
        bad += [f"{d} does not resolve" for d in _DOTTED.findall(span)
                if d not in FORMER and d.rsplit(".", 1)[-1] not in ("c", "h", "py", "json", "md")
                and not _resolves(d)]  # fmt: skip
        for module, names in _FROM.findall(span):
            bad += [f"{module}.{n} does not resolve" for n in (x.strip() for x in names.split(","))
                    if n and not _resolves(f"{module}.{n}")]  # fmt: skip
    return bad


def test_the_files_modules_and_names_the_docs_cite_exist():
    bad = []
    for page in [*sorted(DOCS.glob("*.md")), ROOT / "README.md"]:
        bad += [f"{page.relative_to(ROOT)}: {w}" for w in _doc_citations(page.read_text())]
    assert bad == [], bad


def test_the_docstrings_cite_modules_and_names_that_exist():
    """Absolute (``fte_casadi.design.diagnose``) and relative (``:func:`~.._options.gamma_size```) references in
    the package's docstrings and comments, and the source files they name, exist: a module moved is a reference
    updated. A reference with one leading dot is looked up in its module, then its package (as Sphinx does)."""
    role = re.compile(r":(?:mod|func|class|data|meth|attr|exc):`~?(\.+[\w.]+)`")
    bad = []
    for path in sorted((ROOT / "fte_casadi").rglob("*.py")):
        text, rel = path.read_text(), path.relative_to(ROOT)
        parts = list(rel.with_suffix("").parts)
        module, pkg = ".".join(parts), parts[:-1]
        bad += [f"{rel}: {d}" for d in set(_DOTTED.findall(text))
                if d.rsplit(".", 1)[-1] not in ("c", "h", "py", "json", "md") and not _resolves(d)]  # fmt: skip
        bad += [f"{rel}: {w}" for m in _PATH.finditer(text) if "/" in m.group(1)
                and (w := _cited_file(m.group(1), None))]  # fmt: skip
        for ref in set(role.findall(text)):
            lead = len(ref) - len(ref.lstrip("."))
            name = ref.lstrip(".")
            places = [".".join(pkg[: len(pkg) - lead + 1] + [name])] + (
                [f"{module}.{name}"] if lead == 1 else []
            )
            if not any(_resolves(p) for p in places):
                bad.append(f"{rel}: {ref}")
    assert bad == [], bad


def test_the_citation_checks_see_what_they_are_for():
    assert _doc_citations("`design/sdp.py`") == ["design/sdp.py does not exist"]
    assert _doc_citations("`design/_recertify.py: certify`") == []
    assert _doc_citations("`design/_recertify.py: nothing`") == ["design/_recertify.py defines no nothing"]
    assert _doc_citations("(`fte_casadi.design.bounds`)") == ["fte_casadi.design.bounds does not resolve"]
    assert _doc_citations("```\nfrom fte_casadi.tune import write_outputs, nope\n```") == [
        "fte_casadi.tune.nope does not resolve"
    ]
    assert _doc_citations("`_trust.py`, `_report.py`, `_x.py`") == ["_trust.py does not exist"]


def test_one_version_read_from_the_package_metadata():
    """``fte_casadi.__version__`` is pyproject.toml's version, read from the installed metadata; nothing else in the
    package writes or reads a version of its own (the generated C and the FMU say the same one)."""
    from importlib.metadata import version

    import fte_casadi
    from fte_casadi.codegen._generate import _version

    written = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M).group(1)
    assert fte_casadi.__version__ == version("fte_casadi") == written == _version()
    elsewhere = [str(p.relative_to(ROOT)) for p in (ROOT / "fte_casadi").rglob("*.py")
                 if p.name != "_version.py" and re.search(r'__version__ = |version\("fte_casadi"\)', p.read_text())]  # fmt: skip
    assert elsewhere == []
