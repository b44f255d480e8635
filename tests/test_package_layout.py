"""The shape of the package: no import circles (not even through imports inside functions); what issue #20
found written several times (the symmetric part, the solver statuses, nice rounding, the compiler lookup)
written once; one class per name."""

from __future__ import annotations

import ast
import functools
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1] / "fte_casadi"


@functools.cache
def _parsed(path: pathlib.Path) -> ast.Module:
    """A file's syntax tree, parsed once for the whole module (read only: import_graph parses its own to edit)."""
    return ast.parse(path.read_text())


def _modules() -> dict[str, pathlib.Path]:
    out = {}
    for p in ROOT.rglob("*.py"):
        parts = list(p.relative_to(ROOT.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        out[".".join(parts)] = p
    return out


def import_graph() -> dict[str, set[str]]:
    """Module -> the package's modules it imports anywhere (top level or in a function), type-only
    imports (``if TYPE_CHECKING:``) left out; ``from . import x`` counts as importing ``x``."""
    mods = _modules()
    edges: dict[str, set[str]] = {m: set() for m in mods}
    for m, path in mods.items():
        tree = ast.parse(path.read_text())
        for node in ast.walk(tree):
            if isinstance(node, ast.If) and "TYPE_CHECKING" in ast.unparse(node.test):
                node.body = []
        pkg = m.split(".") if path.name == "__init__.py" else m.split(".")[:-1]
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom):
                base = pkg[: len(pkg) - node.level + 1] if node.level else []
                name = ".".join(base + ([node.module] if node.module else []))
                subs = [f"{name}.{a.name}" for a in node.names if f"{name}.{a.name}" in mods]
                targets = subs if len(subs) == len(node.names) else [name, *subs]
            elif isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            else:
                continue
            edges[m] |= {t for t in targets if t in mods and t != m}
    return edges


def _cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: list[list[str]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                comp.append(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(sorted(comp))

    for v in edges:
        if v not in index:
            visit(v)
    return out


@pytest.mark.slow
def test_the_graph_sees_imports_inside_functions():
    g = import_graph()
    assert "fte_casadi.sim._cluster" in g["fte_casadi.sim._engine"]  # imported at the top
    assert "fte_casadi.bench" in g["fte_casadi.cli._bench"]  # imported inside `fte bench`
    assert _cycles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == [["a", "b", "c"]]


def test_no_import_circles():
    assert _cycles(import_graph()) == []


#: the steps of the path of the data, lowest first (docs/layout.md): a module imports its own step's
#: modules and those of lower steps only
LAYERS = (
    {
        "errors",
        "_rounding",
        "_text",
        "_toolchain",
        "verdicts",
        "interop",
        "_resources",
        "_atomic",
        "_labels",
        "_interrupt",
        "_version",
        "_keywords",
        "_progress",
    },
    {"model"},
    {"ts"},
    {"design"},
    {"step"},
    {"sim", "codegen"},
    {"plants", "plot"},
    {"tune"},
    {"bench", "_report", "_generated", "trust"},
    {"cli", "__init__", "__main__"},
)


def _layer(module: str) -> int:
    part = module.split(".")[1] if "." in module else "__init__"
    return next(k for k, names in enumerate(LAYERS) if part in names)


@pytest.mark.slow
def test_no_module_imports_a_layer_above_it():
    g = import_graph()
    assert {m.split(".")[1] for m in g if "." in m} <= set().union(*LAYERS)  # every top-level part placed
    up = sorted(f"{a} -> {b}" for a, bs in g.items() for b in bs if _layer(b) > _layer(a))
    assert up == []
    assert _layer("fte_casadi.design._api") > _layer("fte_casadi.ts._model")  # design may read ts, not back


# -- written once (issue #20, "one name per concept") ---------------------------------------------------
#: the benchmarks (fte_casadi/bench/) hold baselines written as they were or written by hand on purpose
#: (the per-path engine, a hand-written C loop; the 0.1 design is outside the package, in baselines/): the rules
#: of "written once" below are about the package's own code, which the benchmarks measure
BASELINES = "bench/"


def _where(pred) -> list[str]:
    """``module:line`` of every AST node of the package (not the benchmarks' baselines) for which
    ``pred(node)`` holds."""
    out = []
    for path in sorted(ROOT.rglob("*.py")):
        if path.relative_to(ROOT).as_posix().startswith(BASELINES):
            continue
        for node in ast.walk(_parsed(path)):
            if pred(node):
                out.append(f"{path.relative_to(ROOT).as_posix()}:{node.lineno}")
    return out


def _is_sym(node) -> bool:
    """``0.5 * (M + M.T)``: the symmetric part, written out."""
    if not (isinstance(node, ast.BinOp) and isinstance(node.op, ast.Mult)):
        return False
    inner = node.right if isinstance(node.left, ast.Constant) else node.left
    return (
        isinstance(inner, ast.BinOp)
        and isinstance(inner.op, ast.Add)
        and ast.unparse(inner.right) == f"{ast.unparse(inner.left)}.T"
    )


def _calls(name: str):
    return lambda node: isinstance(node, ast.Call) and ast.unparse(node.func) == name


def _modules_of(places: list[str]) -> set[str]:
    return {p.split(":")[0] for p in places}


@pytest.mark.slow
def test_the_symmetric_part_is_written_once():
    assert _where(_is_sym) == ["design/core/_linalg.py:12"]
    assert _is_sym(ast.parse("0.5 * (P.value + P.value.T)").body[0].value)  # the check sees an inline one


@pytest.mark.slow
def test_the_solver_statuses_nice_rounding_and_compiler_lookup_are_written_once():
    inaccurate = _where(lambda n: isinstance(n, ast.Constant) and n.value == "optimal_inaccurate")
    assert _modules_of(inaccurate) == {"design/core/_sdp.py"} and len(inaccurate) == 1  # SOLVED
    assert _modules_of(_where(_calls("math.log10")) + _where(_calls("np.log10"))) <= {
        "_rounding.py",
        "design/core/_conditioned.py",  # the span of the bracket in a message, not a rounding
        "design/diagnose/_time_unit.py",  # a rate's distance from 1 in decades, not a rounding
    }
    assert _modules_of(_where(_calls("shutil.which"))) == {"_toolchain.py"}


@pytest.mark.slow
def test_one_class_per_name():
    """Two unrelated classes were both called ``Layout`` (the conic layer's and the engine's path layout)."""
    seen: dict[str, list[str]] = {}
    for place in _where(lambda n: isinstance(n, ast.ClassDef)):
        path, line = place.split(":")
        tree = _parsed(ROOT / path)
        name = next(n.name for n in ast.walk(tree) if isinstance(n, ast.ClassDef) and n.lineno == int(line))
        seen.setdefault(name, []).append(place)
    assert {k: v for k, v in seen.items() if len(v) > 1} == {}
    assert "Layout" in seen and "PathLayout" in seen


def test_every_exception_class_lives_in_errors_py():
    from fte_casadi import errors

    def is_exception(node) -> bool:
        return isinstance(node, ast.ClassDef) and any(
            ast.unparse(b).split(".")[-1].endswith(("Error", "Exception", "Warning")) for b in node.bases
        )

    assert _modules_of(_where(is_exception)) == {"errors.py"}
    assert not issubclass(
        errors.SolverFailedError, errors.InfeasibleDesignError
    )  # a failure, not infeasibility


@pytest.mark.slow
def test_the_method_text_is_shown_not_parsed():
    """``TSModel.method`` is display text; code decides on ``TSModel.kind``."""

    def reads_method(node) -> bool:
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute):
            return ast.unparse(node.func.value).endswith(".method") and node.func.attr in (
                "startswith",
                "endswith",
            )
        return isinstance(node, ast.Compare) and any(
            ast.unparse(x).endswith(".method")
            and not ast.unparse(x).startswith("plant.")  # Plant.method is a kind
            for x in (node.left, *node.comparators)
        )

    assert _where(reads_method) == []


def test_a_module_declares_public_only_what_its_package_exports_or_the_docs_name():
    """The public surface (docs/api.md): each subpackage's ``__init__`` re-exports its public names
    (``from ._x import Y as Y``); another module's ``__all__`` lists only those, or names the docs
    document. Everything else is internal, even without a leading underscore."""
    import importlib
    import re

    docs = " ".join(p.read_text() for p in (ROOT.parent / "docs").glob("*.md"))
    docs += (ROOT.parent / "README.md").read_text()
    bad = []
    for init in sorted(ROOT.glob("*/__init__.py")):
        pkg = importlib.import_module(f"fte_casadi.{init.parent.name}")
        exported = {n for n in vars(pkg) if not n.startswith("_")}
        for mod in sorted(init.parent.glob("*.py")):
            rel = f"{init.parent.name}/{mod.name}"
            if (
                mod.name == "__init__.py"
                or rel in NOT_TRIMMED_YET
                or init.parent.name in NOT_TRIMMED_YET_PACKAGES
            ):
                continue
            m = importlib.import_module(f"fte_casadi.{init.parent.name}.{mod.stem}")
            for n in getattr(m, "__all__", []):
                if n not in exported and not re.search(r"`[^`]*\b" + re.escape(n) + r"\b[^`]*`", docs):
                    bad.append(f"{init.parent.name}/{mod.name}: {n}")
    assert bad == [], bad


#: modules whose ``__all__`` is not trimmed yet: work in progress on other branches rewrites them
#: (the fault shapes, the C templates, the T-S groups)
NOT_TRIMMED_YET = {"sim/_scenario.py", "codegen/_template.py"}
NOT_TRIMMED_YET_PACKAGES = {"ts"}


def test_the_exemptions_name_files_that_exist():
    assert all((ROOT / f).is_file() for f in NOT_TRIMMED_YET), sorted(f for f in NOT_TRIMMED_YET
                                                                        if not (ROOT / f).is_file())  # fmt: skip
    assert all((ROOT / p).is_dir() for p in NOT_TRIMMED_YET_PACKAGES)
    assert all((ROOT / f).exists() for f in TEXT_READ)
    assert all((ROOT / f).exists() for f, _ in REACHES)


def reaches() -> set[tuple[str, str]]:
    """``(importer, module)`` for every import of a private module of another subpackage (``fte_casadi.sim._engine``
    from ``bench/_mc.py``); the importer as a path under fte_casadi/, the subpackage of a top-level module is
    its own name."""
    mods = _modules()
    out = set()
    for m, targets in import_graph().items():
        src = m.split(".")[1] if m.count(".") >= 1 else ""
        for t in targets:
            parts = t.split(".")
            if len(parts) < 3 or not (ROOT / parts[1]).is_dir() or parts[1] == src:
                continue
            if any(p.startswith("_") for p in parts[2:]):
                out.add((mods[m].relative_to(ROOT).as_posix(), t))
    return out


#: the imports that reach into another subpackage's private module rather than use its ``__init__`` (its face),
#: by importer (a file, or a folder/) and the subpackage reached, each with its reason
REACHES = {
    (
        "bench/",
        "sim",
    ): "the benchmarks time the engine's parts and run the per-path engine, its baseline: the "
    "random numbers' tail, the vector emitter's operation tables, the prepared closed loop",
    (
        "bench/",
        "codegen",
    ): "the C step's benchmark builds the generated code with the hand-written loop beside it",
    ("cli/_simulate.py", "sim"): "the sweep (fte sweep); sim/__init__.py is rewritten on the fault-detection "
    "branch: to its face when that lands",
    ("plot/_figures.py", "sim"): "the runs' titles; to sim's face with the sweep",
    ("tune/_search.py", "sim"): "the cluster's client and the plant's bytes; to sim's face with the sweep",
}


def _reached(importer: str, module: str) -> tuple[str, str] | None:
    sub = module.split(".")[1]
    return next((k for k in REACHES if k[1] == sub and (importer == k[0] or importer.startswith(k[0]))), None)


def test_subpackages_use_each_others_faces():
    """Other subpackages use a subpackage's ``__init__`` (its face: the public names in ``__all__``, and the
    internal ones the other subpackages need); the few imports of a private module are listed with their reason
    in :data:`REACHES`, and an entry no import needs any more is dropped."""
    found = reaches()
    assert sorted(f"{i} -> {m}" for i, m in found if _reached(i, m) is None) == []
    assert {_reached(i, m) for i, m in found} == set(REACHES)
    assert len(REACHES) <= 6


def test_one_public_init_per_subpackage():
    """A small public surface: inside a subpackage every module but ``__init__.py`` is private
    (``_name.py``); at the top only the modules docs/api.md names public are not."""
    public_top = {"__init__", "__main__", "errors", "step", "interop", "trust", "verdicts"}
    bad = [str(p.relative_to(ROOT)) for p in ROOT.rglob("*.py")
           if not p.stem.startswith("_") and (p.parent != ROOT or p.stem not in public_top)]  # fmt: skip
    assert bad == [], bad


# -- a cause is a record, read by field (docs/layout.md; errors.Refusal) ---------------------------------------------
#: names a message's text goes by in the package's code (the text of an exception, a reason, a status line)
_TEXT_NAMES = {"why", "msg", "message", "text", "reason", "stop", "status", "note", "detail", "advice", "statement",
               "err", "exc", "error"}  # fmt: skip
#: what is done to a text to read it, besides ``in``
_READS = {"startswith", "endswith", "split", "rsplit", "partition", "rpartition", "find", "index", "count"}


def _is_text(node) -> bool:
    """Does ``node`` read as the text of a message: ``str(...)``, a name of :data:`_TEXT_NAMES` (also as an
    attribute, indexed, inside ``a or b``, or read with ``.get("why")``)?"""
    if isinstance(node, ast.Call):
        f = node.func
        if isinstance(f, ast.Name) and f.id == "str":
            return True
        return (isinstance(f, ast.Attribute) and f.attr == "get" and bool(node.args)
                and isinstance(node.args[0], ast.Constant) and node.args[0].value in _TEXT_NAMES)  # fmt: skip
    if isinstance(node, ast.BoolOp):
        return any(_is_text(v) for v in node.values)
    if isinstance(node, ast.Subscript):
        return _is_text(node.value)
    if isinstance(node, ast.Attribute):
        return node.attr in _TEXT_NAMES
    return isinstance(node, ast.Name) and node.id in _TEXT_NAMES


def _reads_a_message(node) -> bool:
    """``"..." in why``, ``"alpha" not in str(exc)``, ``why.startswith("phase 1")``, ``str(err).split(" No ...")``:
    a decision (or a cut) made on the text of a message. ``" ".join(str(exc).split())`` (whitespace) is not."""
    if isinstance(node, ast.Compare):
        lefts = [node.left, *node.comparators]
        return any(isinstance(op, (ast.In, ast.NotIn)) and isinstance(left, (ast.Constant, ast.JoinedStr))
                   and _is_text(right) for op, left, right in zip(node.ops, lefts, node.comparators))  # fmt: skip
    if isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute) and node.func.attr in _READS:
        return _is_text(node.func.value) and bool(node.args)
    return False


#: text read on purpose, with the reason: a documented format, or another library's words
TEXT_READ = {
    "design/_record.py": "a document's `nonfinite` entries are 'NaN: why', a documented format read back; and "
    "their keys are dotted paths",
    "design/core/_sdp.py": "the first sentence of cvxpy's warnings, quoted in the solve's notes",
    "cli/_tune.py": "fte tune counts the failed trials by the first clauses of their reasons, numbers masked: a "
    "display of tune.json's reasons, no decision",
}


def test_no_branch_reads_the_text_of_a_message():
    """Code decides on a refusal's record (``exc.refusal.kind``, ``.lmi``, ``.bounded``, ``.found``), a status
    constant or a number, never on the words of a message: rewording one changes no behaviour."""
    found = _where(_reads_a_message)
    assert [p for p in found if p.split(":")[0] not in TEXT_READ] == []
    assert _modules_of(found) == set(TEXT_READ)  # an exemption whose reason is gone is dropped


def test_the_check_sees_the_message_reads_it_is_for():
    for src in ('"alpha" not in str(exc)', '"(46)" in why', 'st.status.startswith("phase 1")',
                'str(err).split(" No value tried")[0]', '"lowered" in (d.observer.why or "")',
                'why = "sample time" in best.observer.get("why")', 'stop.startswith("stiff")',
                '"time budget" in str(exc)', 'msg.partition(":")'):  # fmt: skip
        assert any(_reads_a_message(n) for n in ast.walk(ast.parse(src))), src
    for src in ('" ".join(str(exc).split())', '"kappa" in resolved.params', 'k in names', 'str(exc).rstrip(".")',
                'res.status not in SOLVED', 'f"{why}: {msg}"', 'exc.refusal.kind in ASKED'):  # fmt: skip
        assert not any(_reads_a_message(n) for n in ast.walk(ast.parse(src))), src


def _room_imports_of_face_names(path: pathlib.Path) -> list[str]:
    """``from fte_casadi.x._y import A`` in ``path`` where every name is the same object on ``fte_casadi.x``'s
    face: a private module imported where the face serves."""
    import importlib

    out = []
    for node in ast.walk(_parsed(path)):
        if not (isinstance(node, ast.ImportFrom) and node.module and not node.level):
            continue
        parts = node.module.split(".")
        private = next((k for k, c in enumerate(parts) if c.startswith("_")), None)
        if parts[0] != "fte_casadi" or private is None or private < 2:
            continue
        face, room = importlib.import_module(".".join(parts[:private])), importlib.import_module(node.module)
        names = [a.name for a in node.names]
        if all(not n.startswith("_") and getattr(face, n, None) is getattr(room, n) for n in names):
            out.append(f"{path.name}:{node.lineno}: {node.module} {names}")
    return out


def test_the_tests_use_the_faces_where_they_can(tmp_path):
    """A test imports a subpackage's private module only for an internal it tests (a name not on the face, or the
    module itself to patch it)."""
    tests = pathlib.Path(__file__).resolve().parent
    assert [w for p in sorted(tests.glob("*.py")) for w in _room_imports_of_face_names(p)] == []
    probe = tmp_path / "probe.py"
    probe.write_text(
        "from fte_casadi.design._record import Design\nfrom fte_casadi.design._record import _arr\n"
    )
    assert _room_imports_of_face_names(probe) == ["probe.py:1: fte_casadi.design._record ['Design']"]


# -- functions short enough to hold in the head (issue #41 item 7) ---------------------------------------------------
#: the most lines (signature, docstring and body) a function of the package may take outside :data:`LONG_FUNCTIONS`
LONG = 80
#: the functions allowed over :data:`LONG` lines, each with its reason; the list may only shrink (an entry whose
#: function got short enough, or went away, is dropped: the test says so)
LONG_FUNCTIONS = {
    # numerical kernels, read as the formulas they implement (docs/method.md)
    "step.py:step_function": "the discrete step, the single source of truth of the simulation and the C: one "
    "CasADi graph read top to bottom against docs/method.md, its sample's operations in order",
    # code emitters: the text they write, in the order it is written
    "codegen/_generate.py:_wrapper": "emits the C wrapper of the step line by line, in the order of the file",
    "sim/_vector.py:emit": "emits the lane engine's C kernel line by line, in the order of the file",
    "sim/_vector.py:_driver": "emits the lane engine's C driver loop line by line, in the order of the file",
    # the benchmarks' baselines, kept as they were written (docs/benchmarks.md)
    "bench/_perpath.py:simulate_per_path": "the per-path engine, the baseline and test oracle, kept as written",
    # design/ is being rewritten on another branch (#41 item 2, the LMI registry that poses): split there
    "design/_api.py:explore": "design/ is rewritten on another branch now; split with it",
    "design/_pipeline.py:finish": "design/ is rewritten on another branch now; split with it",
    "design/_docchecks.py:check_document": "design/ is rewritten on another branch now; split with it",
    "design/_record.py:Design.from_dict": "design/ is rewritten on another branch now; split with it",
    "design/core/_step5.py:step5": "step 5's SDP (LMIs (46), (55), (64)); design/ is rewritten on another "
    "branch now (the registry that poses the LMIs replaces its hand-assembled constraints)",
}


def long_functions(limit: int = LONG) -> dict[str, int]:
    """``{"path:qualified.name": lines}`` of the package's functions (and methods) over ``limit`` lines."""
    out = {}

    def visit(node, prefix: str, rel: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                name = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef) and child.end_lineno - child.lineno + 1 > limit:
                    out[f"{rel}:{name}"] = child.end_lineno - child.lineno + 1
                visit(child, f"{name}.", rel)

    for path in sorted(ROOT.rglob("*.py")):
        visit(_parsed(path), "", path.relative_to(ROOT).as_posix())
    return out


def test_no_function_grows_past_80_lines_outside_the_reasoned_list():
    found = long_functions()
    assert sorted(f"{k} ({v} lines)" for k, v in found.items() if k not in LONG_FUNCTIONS) == []
    assert sorted(set(LONG_FUNCTIONS) - set(found)) == []  # short enough now, or gone: drop its entry
    assert long_functions(10_000) == {}
    assert "design/_record.py:Design.from_dict" in long_functions(60)  # the walk sees methods, by their class
