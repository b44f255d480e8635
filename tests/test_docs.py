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
