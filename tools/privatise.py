"""A small public surface (one public ``__init__`` per subpackage, as diffrax does): make every module of a
subpackage private (``design/api.py`` -> ``design/_api.py``) and the top-level modules that are not public
API, and rewrite every reference to them.

Run from the repository root, on a clean tree::

    python tools/privatise.py            # git mv + rewrite; prints what it did
    python tools/privatise.py --dry-run  # only print the renames

Idempotent: a second run finds no public module left to rename and changes nothing. The public top-level
modules are :data:`KEEP_PUBLIC` (docs/api.md, "What is public"). What it rewrites, in the package,
tests/, examples/, benchmarks/, docs/*.md, mkdocs.yml, README.md and pyproject.toml:

- dotted paths (``fte_casadi.design.api`` -> ``fte_casadi.design._api``), also in strings, ``:::`` lines
  and ``python -m`` commands; where a module shares its name with what its package re-exports
  (``fte_casadi.sim.metrics`` is the function), a bare path is read as the module only after ``import``,
  ``from``, ``-m`` or a quote; in the docs, ``fte_casadi.<pkg>.<mod>.<name>`` becomes
  ``fte_casadi.<pkg>.<name>`` where the package re-exports ``name``;
- ``from`` imports: the relative module (``from ..ts.model import`` -> ``from ..ts._model import``) and
  submodules imported by name (``from . import pipeline`` -> ``from . import _pipeline as pipeline``,
  also ``from fte_casadi.codegen import build``), keeping the local name; a name that the package binds
  to something else (``from fte_casadi.plants import manipulator``, the function) is left alone;
- relative Sphinx roles in docstrings (``:mod:`.lmis``` -> ``:mod:`._lmis```);
- file paths (``fte_casadi/design/api.py``, ``design/core/lmis.py``, a bare ``rounding.py`` of a private
  top-level module; bare sibling names in the package's own docstrings; docs/layout.md's trees);
- names the docs cite by module path (``fte_casadi.sim.accommodate.accommodated``) are re-exported by
  their package's ``__init__``;
- tests/test_package_layout.py's layers name the private top-level modules, and a test of the new rule
  is added; docs/layout.md and docs/api.md say the rule.

Afterwards it runs ``ruff check --select I --fix`` and ``ruff format`` on the Python files it changed (the
import order changes with the leading underscore). ``generated/`` is not touched.
"""

from __future__ import annotations

import argparse
import ast
import re
import shutil
import subprocess
import sys
from pathlib import Path

PKG = "fte_casadi"
#: top-level modules that stay public: docs/api.md's "What is public" names them (errors: users catch
#: its exceptions; step: step_function; interop: python-control); __init__/__main__ are not modules to hide
KEEP_PUBLIC = {"__init__", "__main__", "errors", "step", "interop", "trust", "verdicts"}
#: where references are rewritten (globs from the repository root)
TARGETS = (
    f"{PKG}/**/*.py",
    "tests/**/*.py",
    "examples/**/*.py",
    "examples/**/*.md",
    "benchmarks/**/*.py",
    "benchmarks/**/*.md",
    "docs/*.md",
    "mkdocs.yml",
    "README.md",
    "pyproject.toml",
)

IDENT = r"[A-Za-z_][A-Za-z0-9_]*"


class Tree:
    """The package as it is before the change: its packages, the modules to rename, and the names each
    package's ``__init__`` binds to something other than a submodule."""

    def __init__(self, root: Path):
        self.root = root
        self.packages: set[str] = set()
        self.modules: set[str] = set()  # every module (dotted), packages excluded
        self.rename: dict[str, str] = {}  # dotted module -> dotted private module
        for init in sorted((root / PKG).rglob("__init__.py")):
            self.packages.add(".".join(init.parent.relative_to(root).parts))
        for path in sorted((root / PKG).rglob("*.py")):
            parent = ".".join(path.parent.relative_to(root).parts)
            if parent not in self.packages or path.stem == "__init__":
                continue
            dotted = f"{parent}.{path.stem}"
            self.modules.add(dotted)
            if path.stem.startswith("_"):
                continue
            if parent == PKG and path.stem in KEEP_PUBLIC:
                continue
            self.rename[dotted] = f"{parent}._{path.stem}"
        self.bound = {p: self._bound_names(p) for p in self.packages}

    def path_of(self, dotted: str) -> Path:
        parts = dotted.split(".")
        if dotted in self.packages:
            return self.root.joinpath(*parts, "__init__.py")
        return self.root.joinpath(*parts[:-1], parts[-1] + ".py")

    def _bound_names(self, package: str) -> set[str]:
        """Names ``package/__init__.py`` binds at its top level to objects that are not its submodules."""
        tree = ast.parse(self.path_of(package).read_text())
        out: set[str] = set()
        for node in tree.body:
            if isinstance(node, ast.ImportFrom):
                base = resolve_from(package, True, node.level, node.module)
                for a in node.names:
                    if f"{base}.{a.name}" not in self.modules | self.packages or a.asname not in (
                        None,
                        a.name,
                    ):
                        out.add(a.asname or a.name)
            elif isinstance(node, (ast.FunctionDef, ast.ClassDef)):
                out.add(node.name)
            elif isinstance(node, ast.Assign):
                out |= {t.id for t in node.targets if isinstance(t, ast.Name)}
        return out

    def reexported(self, package: str) -> dict[str, str]:
        """Name -> the module it comes from, for ``from .mod import name as name`` lines of the ``__init__``."""
        tree = ast.parse(self.path_of(package).read_text())
        out = {}
        for node in tree.body:
            if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
                for a in node.names:
                    if a.asname in (None, a.name):
                        out[a.name] = f"{package}.{node.module}"
        return out


def resolve_from(package: str, is_init: bool, level: int, module: str | None) -> str:
    """The absolute dotted name of ``from <level dots><module> import`` written in a module of
    ``package`` (``is_init``: in the package's own ``__init__``)."""
    if level == 0:
        return module or ""
    parts = package.split(".")
    if not is_init:
        parts = parts[:-1]  # ``package`` is the module's dotted name here: its package is one up
    parts = parts[: len(parts) - level + 1]
    return ".".join(parts + ([module] if module else []))


def private_dotted(tree: Tree, dotted: str, *, bare_is_module: bool = True) -> str:
    """``dotted`` with its module component made private, if it names one to rename."""
    parts = dotted.split(".")
    if parts[0] != PKG:
        return dotted
    cur = PKG
    for i in range(1, len(parts)):
        nxt = f"{cur}.{parts[i]}"
        if nxt in tree.packages:
            cur = nxt
            continue
        if nxt in tree.rename:
            last = i == len(parts) - 1
            if last and parts[i] in tree.bound[cur] and not bare_is_module:
                return dotted  # the package's attribute of that name (a function), not the module
            parts[i] = "_" + parts[i]
        return ".".join(parts)
    return dotted


# -- text rewrites -----------------------------------------------------------------------------------------
DOTTED = re.compile(rf"(?<![\w.]){PKG}((?:\.{IDENT})+)")
MODULE_CONTEXT = re.compile(r"(?:\bimport\s+|\bfrom\s+|-m\s+|[\"'])$")


def rewrite_dotted(tree: Tree, text: str, *, docs: bool) -> str:
    def sub(m: re.Match) -> str:
        old = m.group(0)
        before = text[max(0, m.start() - 12) : m.start()]
        new = private_dotted(tree, old, bare_is_module=bool(MODULE_CONTEXT.search(before)))
        if docs and new != old:
            new = public_in_docs(tree, old, new, text, m.start())
        return new

    return DOTTED.sub(sub, text)


def public_in_docs(tree: Tree, old: str, new: str, text: str, start: int) -> str:
    """In the docs, ``fte_casadi.<pkg>.<mod>.<name>`` -> ``fte_casadi.<pkg>.<name>`` where the package
    re-exports ``name`` from that module (not on ``:::`` lines, in anchors or in commands)."""
    line_start = text.rfind("\n", 0, start) + 1
    line = text[line_start:start]
    if line.lstrip().startswith(":::") or line.endswith(("#", "-m ", "import ", "from ")):
        return new
    parts = old.split(".")
    for i in range(2, len(parts) - 1):
        pkg, mod = ".".join(parts[:i]), ".".join(parts[: i + 1])
        if mod in tree.rename and pkg in tree.packages:
            name = parts[i + 1]
            if tree.reexported(pkg).get(name) == mod or name in tree.extra_exports.get(pkg, {}):
                return ".".join([pkg, *parts[i + 1 :]])
            return new
    return new


ROLE = re.compile(rf":(\w+):`(~?)(\.+)({IDENT}(?:\.{IDENT})*)`")


def rewrite_roles(tree: Tree, text: str, module: str, is_init: bool) -> str:
    def sub(m: re.Match) -> str:
        level = len(m.group(3))
        base = resolve_from(module, is_init, level, None)
        absolute = f"{base}.{m.group(4)}"
        new = private_dotted(tree, absolute)
        if new == absolute:
            return m.group(0)
        return f":{m.group(1)}:`{m.group(2)}{m.group(3)}{new[len(base) + 1 :]}`"

    return ROLE.sub(sub, text)


PATH = re.compile(rf"(?<![\w./-])((?:{PKG}/)?)((?:{IDENT}/)*)({IDENT})\.py\b")


def private_path(tree: Tree, prefix: str, dirs: str, name: str, siblings: str | None) -> str | None:
    """The private form of a file path, or None. ``siblings``: the dotted package whose modules a bare
    name may mean besides the private top-level ones."""
    if prefix or dirs:
        if not prefix and f"{PKG}.{dirs.split('/')[0]}" not in tree.packages:
            return None
        dotted = ".".join([PKG, *dirs.strip("/").split("/"), name]) if dirs else f"{PKG}.{name}"
        if dotted in tree.rename:
            return f"{prefix}{dirs}_{name}.py"
        return None
    for pkg in ([siblings] if siblings else []) + [PKG]:
        if f"{pkg}.{name}" in tree.rename:
            return f"_{name}.py"
    return None


def rewrite_paths(tree: Tree, text: str, siblings: str | None = None) -> str:
    def sub(m: re.Match) -> str:
        return private_path(tree, m.group(1), m.group(2), m.group(3), siblings) or m.group(0)

    return PATH.sub(sub, text)


def rewrite_layout_trees(tree: Tree, text: str) -> str:
    """docs/layout.md: the bare file names of its trees (``design/``, ``  core/``, ``cli/``) read in the
    folder they are drawn in; elsewhere a bare name unique among the package's modules."""
    out, in_block, stack, folder = [], False, [], PKG
    by_name: dict[str, list[str]] = {}
    for d in tree.rename:
        by_name.setdefault(d.rsplit(".", 1)[1], []).append(d)
    for line in text.split("\n"):
        if line.startswith("```"):
            in_block, stack, folder = not in_block, [], PKG
            out.append(line)
            continue
        if in_block:
            depth = (len(line) - len(line.lstrip())) // 2
            m = re.match(r"^(\s*)(\w+)/(\s|$)", line)
            if m and depth <= len(stack):
                stack = stack[:depth] + [m.group(2)]
                folder = ".".join([PKG, *stack])
            elif depth <= len(stack):  # an entry; deeper lines continue the last entry's description
                folder = ".".join([PKG, *stack[:depth]])
            chain = [".".join(folder.split(".")[:k]) for k in range(len(folder.split(".")), 0, -1)]

            def sub(m: re.Match, chain=chain) -> str:
                if m.group(1) or m.group(2):
                    return private_path(tree, m.group(1), m.group(2), m.group(3), None) or m.group(0)
                for pkg in chain:
                    if f"{pkg}.{m.group(3)}" in tree.modules:
                        return f"_{m.group(3)}.py" if f"{pkg}.{m.group(3)}" in tree.rename else m.group(0)
                return m.group(0)

            head = re.match(r"^(\s*\S.*?)( {2,}|$)(.*)$", line)  # the entry, its padding, its description
            if head:
                name = PATH.sub(sub, head.group(1))
                pad = head.group(2)[: max(1, len(head.group(2)) - (len(name) - len(head.group(1))))]
                out.append(name + (pad if head.group(2) else "") + PATH.sub(sub, head.group(3)))
            else:
                out.append(line)
        else:

            def sub(m: re.Match, by_name=by_name) -> str:
                if m.group(1) or m.group(2):
                    return private_path(tree, m.group(1), m.group(2), m.group(3), None) or m.group(0)
                hits = by_name.get(m.group(3), [])
                if f"{PKG}.{m.group(3)}" in tree.rename or len(hits) == 1:
                    return f"_{m.group(3)}.py"
                return m.group(0)

            out.append(PATH.sub(sub, line))
    return "\n".join(out)


def rewrite_from_imports(tree: Tree, text: str, module: str | None, is_init: bool) -> str:
    """The ``from`` imports of a Python file: the relative module part, and submodules imported by name
    (``from . import x`` -> ``from . import _x as x``). ``module``: the file's dotted name inside the
    package (None outside it: only absolute imports are read)."""
    try:
        parsed = ast.parse(text)
    except SyntaxError:
        return text
    lines = text.split("\n")
    offsets = [0]
    for ln in lines:
        offsets.append(offsets[-1] + len(ln.encode()) + 1)
    data = text.encode()
    edits = []
    for node in ast.walk(parsed):
        if not isinstance(node, ast.ImportFrom):
            continue
        if node.level and module is None:
            continue
        base = resolve_from(module or "", is_init, node.level, node.module)
        if not base.startswith(PKG):
            continue
        start = offsets[node.lineno - 1] + node.col_offset
        end = offsets[node.end_lineno - 1] + node.end_col_offset
        seg = data[start:end].decode()
        m = re.match(r"(from\s+)(\.*)([\w.]*)(\s+import\b)(.*)", seg, re.S)
        if not m:
            continue
        mod_text = m.group(3)
        if node.level and mod_text:
            new_abs = private_dotted(tree, base)
            if new_abs != base:
                prefix_len = len(resolve_from(module or "", is_init, node.level, None).split("."))
                mod_text = ".".join(new_abs.split(".")[prefix_len:])
        names = m.group(5)
        if base in tree.packages:

            def sub(mm: re.Match, base=base) -> str:
                name, alias = mm.group(1), mm.group(3)
                dotted = f"{base}.{name}"
                if dotted not in tree.rename or name in tree.bound[base]:
                    return mm.group(0)
                return f"_{name} as {alias or name}"

            pieces = []
            for piece in re.split(r"(#[^\n]*)", names):
                if piece.startswith("#"):
                    pieces.append(piece)
                else:
                    pieces.append(re.sub(rf"(?<![\w.])({IDENT})(\s+as\s+({IDENT}))?", sub, piece))
            names = "".join(pieces)
        new = f"{m.group(1)}{m.group(2)}{mod_text}{m.group(4)}{names}"
        if new != seg:
            edits.append((start, end, new.encode()))
    for start, end, new in sorted(edits, reverse=True):
        data = data[:start] + new + data[end:]
    return data.decode()


# -- re-exports --------------------------------------------------------------------------------------------
def module_all(tree: Tree, dotted: str) -> list[str]:
    for node in ast.parse(tree.path_of(dotted).read_text()).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            try:
                return list(ast.literal_eval(node.value))
            except ValueError:
                return []
    return []


def extra_exports(tree: Tree, docs_text: str) -> dict[str, dict[str, str]]:
    """Package -> {name: module} for names the docs cite by module path (``fte_casadi.<pkg>.<mod>.<name>``),
    listed in the module's ``__all__`` and not yet re-exported by the package: those the ``__init__`` adds."""
    out: dict[str, dict[str, str]] = {}
    for m in DOTTED.finditer(docs_text):
        parts = m.group(0).split(".")
        for i in range(2, len(parts) - 1):
            pkg, mod = ".".join(parts[:i]), ".".join(parts[: i + 1])
            if mod in tree.rename and pkg in tree.packages:
                name = parts[i + 1]
                if name in module_all(tree, mod) and name not in tree.bound[pkg]:
                    if f"{pkg}.{name}" not in tree.modules | tree.packages:
                        out.setdefault(pkg, {})[name] = mod
                break
    return out


def add_reexports(text: str, names: dict[str, str]) -> str:
    """Add ``from ._mod import name as name`` after the ``__init__``'s last top-level relative import, and
    the names to its ``__all__`` if it has one."""
    parsed = ast.parse(text)
    last = max(
        (n for n in parsed.body if isinstance(n, ast.ImportFrom) and n.level), key=lambda n: n.end_lineno
    )
    lines = text.split("\n")
    new = [f"from ._{mod.rsplit('.', 1)[1]} import {name} as {name}" for name, mod in sorted(names.items())]
    lines[last.end_lineno : last.end_lineno] = new
    text = "\n".join(lines)
    m = re.search(r"^__all__ = \[", text, re.M)
    if m:
        text = text[: m.end()] + "".join(f'"{n}", ' for n in sorted(names)) + text[m.end() :]
    return text


# -- the tests and docs that describe the layout -----------------------------------------------------------
LAYOUT_TEST = "tests/test_package_layout.py"
LAYOUT_TEST_ADDED = '''

def test_one_public_init_per_subpackage():
    """A small public surface: inside a subpackage every module but ``__init__.py`` is private
    (``_name.py``); at the top only the modules docs/api.md names public are not."""
    public_top = {"__init__", "__main__", "errors", "step", "interop"}
    bad = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*.py")
           if not p.stem.startswith("_") and (p.parent != ROOT or p.stem not in public_top)]  # fmt: skip
    assert bad == [], bad
'''
LAYOUT_DOC_ANCHOR = "\n## design/\n"
LAYOUT_DOC_ADDED = """
A small public surface: inside each subpackage every module but `__init__.py` is private (`_name.py`), and
the `__init__` re-exports the public names; at the top only `errors.py`, `step.py` and `interop.py` are
public (docs/api.md), the other modules are private (`_report.py`, `_trust.py`, ...).
`tools/privatise.py` made it so.
"""
API_OLD = "(`from .x import Y as Y`, listed in its `__all__`)"
API_NEW = "(`from ._x import Y as Y`, listed in its `__all__`; the modules themselves are private, `_x.py`)"


def special(tree: Tree, rel: str, text: str) -> str:
    if rel == LAYOUT_TEST:
        layers = re.search(
            r"^LAYERS = \(.*?^\)", text, re.S | re.M
        )  # the layers name modules as they are named
        if layers:
            block = re.sub(
                r'"(\w+)"',
                lambda m: f'"_{m.group(1)}"' if f"{PKG}.{m.group(1)}" in tree.rename else m.group(0),
                layers.group(0),
            )
            text = text[: layers.start()] + block + text[layers.end() :]
        else:
            print(f"warning: {rel}: no LAYERS block; check the layers by hand", file=sys.stderr)
        if "def test_one_public_init_per_subpackage" not in text:
            text = text.rstrip("\n") + "\n" + LAYOUT_TEST_ADDED
    elif rel == "docs/layout.md" and "`tools/privatise.py` made it so" not in text:
        if LAYOUT_DOC_ANCHOR in text:
            text = text.replace(LAYOUT_DOC_ANCHOR, LAYOUT_DOC_ADDED + LAYOUT_DOC_ANCHOR, 1)
        else:
            print("warning: docs/layout.md: no '## design/' section to put the rule before", file=sys.stderr)
    elif rel == "docs/api.md" and API_OLD in text:
        text = text.replace(API_OLD, API_NEW)
    return text


# -- the run -----------------------------------------------------------------------------------------------
def files(root: Path) -> list[Path]:
    out: set[Path] = set()
    for pattern in TARGETS:
        out |= {p for p in root.glob(pattern) if p.is_file() and ".egg-info" not in p.as_posix()}
    return sorted(out)


def rewrite(tree: Tree, root: Path, path: Path) -> str:
    rel = path.relative_to(root).as_posix()
    text = path.read_text()
    docs = path.suffix == ".md"
    if path.suffix == ".py":
        module, is_init, siblings = None, False, None
        parts = path.relative_to(root).with_suffix("").parts
        if parts[0] == PKG:
            is_init = parts[-1] == "__init__"
            module = ".".join(parts[:-1] if is_init else parts)
            siblings = ".".join(parts[:-1])
        text = rewrite_from_imports(tree, text, module, is_init)
        if module is not None:
            text = rewrite_roles(tree, text, module, is_init)
        text = rewrite_dotted(tree, text, docs=False)
        text = rewrite_paths(tree, text, siblings)
    elif rel == "docs/layout.md":
        text = rewrite_dotted(tree, text, docs=True)
        text = rewrite_layout_trees(tree, text)
    else:
        text = rewrite_dotted(tree, text, docs=docs)
        text = rewrite_paths(tree, text)
    return special(tree, rel, text)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--dry-run", action="store_true", help="only print the renames")
    args = ap.parse_args()
    root = Path.cwd()
    if not (root / PKG / "__init__.py").is_file():
        print(f"run from the repository root (no {PKG}/__init__.py here)", file=sys.stderr)
        return 2
    tree = Tree(root)
    docs_text = "\n".join(p.read_text() for p in [*root.glob("docs/*.md"), root / "README.md"] if p.is_file())
    tree.extra_exports = extra_exports(tree, docs_text)
    moves = [(tree.path_of(old), tree.path_of(new)) for old, new in sorted(tree.rename.items())]
    for a, b in moves:
        print(f"{a.relative_to(root)} -> {b.relative_to(root)}")
    for pkg, names in tree.extra_exports.items():
        print(f"{pkg}: re-exports {', '.join(f'{n} (from {m})' for n, m in sorted(names.items()))}")
    if args.dry_run or not moves:
        print(f"{len(moves)} module(s) to rename" + ("" if moves else ": nothing to do"))
        return 0

    changed: dict[Path, str] = {}
    for path in files(root):
        new = rewrite(tree, root, path)
        if path.parent.name != PKG and path.name == "__init__.py":
            pkg = ".".join(path.parent.relative_to(root).parts)
            if pkg in tree.extra_exports:
                new = add_reexports(new, tree.extra_exports[pkg])
        if new != path.read_text():
            changed[path] = new
    for path, text in changed.items():
        path.write_text(text)
    for a, b in moves:
        subprocess.run(
            ["git", "mv", str(a.relative_to(root)), str(b.relative_to(root))], cwd=root, check=True
        )
    moved = dict(moves)
    py = sorted(
        {str(moved.get(p, p).relative_to(root)) for p in changed if p.suffix == ".py"}
        | {str(b.relative_to(root)) for _, b in moves}
    )
    ruff = shutil.which("ruff")
    if ruff:
        subprocess.run([ruff, "check", "--select", "I", "--fix", "--quiet", *py], cwd=root, check=False)
        subprocess.run([ruff, "format", "--quiet", *py], cwd=root, check=False)
    else:
        print(
            "warning: ruff not found: run `ruff check --select I --fix . && ruff format .`", file=sys.stderr
        )
    print(f"{len(moves)} module(s) renamed, {len(changed)} file(s) rewritten")
    return 0


if __name__ == "__main__":
    sys.exit(main())
