"""Nothing lost: every output file is written whole or not at all (a kill or a failed write leaves the
previous file), a Ctrl-C exits 130 saying exactly what was written, and ``fte tune`` replaces its
directory as one set and resumes an interrupted search (docs/interface.md, docs/tune.md)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from fte_casadi import _atomic as atomic
from fte_casadi._atomic import atomic_write, atomic_write_text, replace_dir
from fte_casadi.cli import main
from fte_casadi.design import Design
from fte_casadi.errors import SimulationError
from fte_casadi.sim import load_result

ROOT = Path(__file__).resolve().parents[1]
SPEC = f"{Path(__file__).parent / 'plant_tune.py'}:plant"


def _files(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its bytes, by relative path."""
    return {str(f.relative_to(folder)): f.read_bytes() for f in sorted(folder.rglob("*")) if f.is_file()}


def _interruptible() -> None:
    """In the child, before Python starts: Ctrl-C as a terminal gives it. A suite started in the background of a
    non-interactive shell (``pytest &``) ignores SIGINT, the children inherit that, and Python then installs no
    handler: the signals these tests send would be ignored, as they should be for such a process."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def _fte(*args: str, **kw) -> subprocess.Popen:
    """``python -m fte_casadi ARGS`` from this checkout, in its own process, interruptible."""
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    return subprocess.Popen([sys.executable, "-m", "fte_casadi", *args], cwd=ROOT, env=env,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, preexec_fn=_interruptible, **kw)  # fmt: skip


def _said(r) -> str:
    """stderr as one line (messages are wrapped paragraphs)."""
    return " ".join(r.stderr.split())


@pytest.fixture(scope="module")
def small(tmp_path_factory) -> Path:
    """The small plant's design document (fte design)."""
    path = tmp_path_factory.mktemp("design") / "small.json"
    r = CliRunner().invoke(main, ["design", SPEC, "-o", str(path)])
    assert r.exit_code == 0, r.output
    return path


# -- the helper -----------------------------------------------------------------------------
@pytest.mark.parametrize("error", [OSError(28, "No space left on device"), KeyboardInterrupt()])
def test_a_failed_write_leaves_the_old_file_and_no_temporary(tmp_path, error):
    p = tmp_path / "result.npz"
    p.write_bytes(b"old and whole")

    def half(fh):
        fh.write(b"new, half of it")
        raise error

    with pytest.raises(type(error)):
        atomic_write(p, half)
    assert p.read_bytes() == b"old and whole"
    assert sorted(os.listdir(tmp_path)) == ["result.npz"]
    atomic_write_text(p, "new, whole ü")
    assert p.read_text(encoding="utf-8") == "new, whole ü"


def test_the_mode_of_the_file_is_kept_or_that_of_open(tmp_path):
    old = tmp_path / "old.json"
    old.write_text("{}")
    old.chmod(0o640)
    atomic_write_text(old, "[]")
    assert old.stat().st_mode & 0o777 == 0o640
    new = tmp_path / "new.json"
    atomic_write_text(new, "[]")
    plain = tmp_path / "plain.json"
    plain.write_text("[]")
    assert new.stat().st_mode & 0o777 == plain.stat().st_mode & 0o777  # not mkstemp's 0o600


_WRITER = """
import sys, numpy as np
from fte_casadi._atomic import atomic_write
big = np.random.default_rng(0).standard_normal(3_000_000)
for k in range(1, 1000):
    atomic_write(sys.argv[1], lambda fh: np.savez_compressed(fh, k=np.array(k), big=big + k))
"""


def test_a_kill_while_writing_leaves_the_old_or_the_complete_file(tmp_path):
    """SIGKILL while a write is under way (its temporary file seen, an earlier one complete): the file
    loads, whole, and a temporary file is all a kill can leave."""
    target = tmp_path / "r.npz"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    p = subprocess.Popen([sys.executable, "-c", _WRITER, str(target)], env=env)
    try:
        deadline = time.monotonic() + 120
        while not (target.exists() and any(f.name.endswith(".tmp") for f in tmp_path.iterdir())):
            assert p.poll() is None and time.monotonic() < deadline
            time.sleep(0.002)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=30)
    finally:
        p.kill()
    with np.load(target) as z:
        k = int(z["k"])
        np.testing.assert_array_equal(z["big"][:5], np.random.default_rng(0).standard_normal(5) + k)
    assert {f.name for f in tmp_path.iterdir()} - {"r.npz"} <= {f.name for f in tmp_path.glob(".r.npz.*.tmp")}


@pytest.mark.parametrize("exchange", [True, False])
def test_replace_dir_puts_the_new_set_in_place(tmp_path, monkeypatch, exchange):
    old, new = tmp_path / "out", tmp_path / "out.partial"
    (old / "designs").mkdir(parents=True)
    (old / "designs" / "trial-0003.json").write_text("old")
    (old / "tune.json").write_text("old")
    new.mkdir()
    (new / "tune.json").write_text("new")
    if not exchange:
        monkeypatch.setattr(atomic, "_exchange", lambda a, b: False)
    replace_dir(new, old)
    assert _files(old) == {"tune.json": b"new"}
    assert sorted(f.name for f in tmp_path.iterdir()) == ["out"]


@pytest.mark.slow
# -- simulate --save, load_result, design -o ---------------------------------------------------
def test_a_kill_during_simulate_save_leaves_the_earlier_result(small, tmp_path):
    """``fte simulate --save`` killed while the .npz is being written: the earlier result is intact."""
    target = tmp_path / "r.npz"
    r = CliRunner().invoke(
        main, ["simulate", str(small), "--plant", SPEC, "--paths", "2", "--save", str(target), "--quiet"]
    )
    assert r.exit_code == 0, r.output
    before = target.read_bytes()
    p = _fte("simulate", str(small), "--plant", SPEC, "--paths", "40", "--save", str(target), "--quiet")
    try:
        deadline = time.monotonic() + 300
        while not any(f.name.endswith(".tmp") for f in tmp_path.iterdir()):
            assert p.poll() is None, p.stderr.read().decode()
            assert time.monotonic() < deadline
            time.sleep(0.002)
        p.send_signal(signal.SIGKILL)
        p.wait(timeout=30)
    finally:
        p.kill()
        p.communicate()
    assert target.read_bytes() == before
    assert load_result(target).paths == 2


@pytest.mark.slow
def test_load_result_names_a_truncated_file(small, tmp_path):
    target = tmp_path / "r.npz"
    r = CliRunner().invoke(
        main, ["simulate", str(small), "--plant", SPEC, "--paths", "2", "--save", str(target), "--quiet"]
    )
    assert r.exit_code == 0, r.output
    data = target.read_bytes()
    for cut in (len(data) // 2, len(data) - 100, 30):
        target.write_bytes(data[:cut])
        with pytest.raises(SimulationError, match="corrupt or truncated"):
            load_result(target)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["d.json", "d.mat"])
def test_ctrl_c_while_design_writes_leaves_the_earlier_document(small, tmp_path, monkeypatch, name):
    target = tmp_path / name
    r = CliRunner().invoke(main, ["design", SPEC, "-o", str(target)])
    assert r.exit_code == 0, r.output
    before = target.read_bytes()

    real = os.replace

    def interrupted(src, dst):  # the new document is written whole, not yet renamed into place
        if str(dst).startswith(str(tmp_path)):
            raise KeyboardInterrupt
        return real(src, dst)

    monkeypatch.setattr(atomic.os, "replace", interrupted)
    r = CliRunner().invoke(main, ["design", SPEC, "--gamma1", "0.5", "-o", str(target)])
    assert r.exit_code == 130, r.output
    assert "interrupted; nothing was written" in _said(r)
    assert target.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == [name]


@pytest.mark.slow
def test_ctrl_c_names_what_was_written(small, tmp_path, monkeypatch):
    """The result was saved before the Ctrl-C came, the figures were not: the message says so."""
    import fte_casadi.plot as plot

    target, figs = tmp_path / "r.npz", tmp_path / "figs"

    def interrupted(*a, **k):
        raise KeyboardInterrupt

    monkeypatch.setattr(plot, "write_figures", interrupted)
    r = CliRunner().invoke(main, ["simulate", str(small), "--plant", SPEC, "--paths", "2", "--save", str(target), "--plots",
                                  str(figs), "--quiet"])  # fmt: skip
    assert r.exit_code == 130, r.output
    assert f"written before the interrupt, each file complete: {target}; nothing else was written" in _said(r)
    assert load_result(target).paths == 2
    assert not figs.exists()


@pytest.mark.slow
def test_sigint_stops_simulate_within_seconds(small, tmp_path):
    """SIGINT to ``python -m fte_casadi simulate`` in the middle of a long Monte Carlo: exit 130 within
    a few seconds (docs/interface.md: about a second), the earlier figures untouched."""
    figs = tmp_path / "figs"
    figs.mkdir()
    (figs / "fig01_old.png").write_bytes(b"an earlier figure")
    p = _fte("simulate", str(small), "--plant", SPEC, "--paths", "200000", "--plots", str(figs))
    err = bytearray()  # the progress bar rewrites its line (\r): read what comes, not lines
    reader = threading.Thread(target=lambda: [err.extend(b) for b in iter(lambda: p.stderr.read1(4096), b"")],
                              daemon=True)  # fmt: skip
    reader.start()
    try:
        deadline = time.monotonic() + 300
        while b"paths" not in err:  # the progress bar: the Monte Carlo is running
            assert p.poll() is None, err.decode()
            assert time.monotonic() < deadline
            time.sleep(0.05)
        time.sleep(1.0)
        t0 = time.monotonic()
        p.send_signal(signal.SIGINT)
        p.wait(timeout=60)
        stopped = time.monotonic() - t0
    finally:
        p.kill()
    reader.join(timeout=10)
    err = err.decode()
    assert p.returncode == 130, err
    assert stopped < 5.0, f"stopped {stopped:.2f} s after SIGINT"
    print(f"stopped {stopped:.2f} s after SIGINT")
    assert "interrupted; nothing was written" in err
    assert _files(figs) == {"fig01_old.png": b"an earlier figure"}


# -- fte tune ------------------------------------------------------------------------------
pytest.importorskip("optuna")


def _tune(out: Path, *extra: str):
    return CliRunner().invoke(main, ["tune", SPEC, "--seed", "2", "--paths", "2", "--out", str(out), "--quiet",
                                     *extra])  # fmt: skip


def _trials(out: Path) -> list[tuple]:
    return [(t["trial"], t["state"], json.dumps(t["knobs"], sort_keys=True), t["objectives"])
            for t in json.loads((out / "tune.json").read_text())["trials"]]  # fmt: skip


@pytest.mark.slow
def test_tune_interrupted_keeps_its_trials_and_resumes(tmp_path, monkeypatch):
    """An earlier set in DIR survives a Ctrl-C; the finished trials are kept in DIR.partial; --resume
    finishes the run, and its trials are those of an uninterrupted run."""
    import fte_casadi.tune._search as search

    out = tmp_path / "t"
    r = _tune(out, "--trials", "2")
    assert r.exit_code == 0, r.output
    earlier = _files(out)
    assert "optuna.db" in earlier and len(_trials(out)) == 2

    real, calls = search.evaluate, []

    def interrupted_third(task):  # trial 0 and one trial of the next batch, then Ctrl-C
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(task)

    monkeypatch.setattr(search, "evaluate", interrupted_third)
    r = _tune(out, "--trials", "4")
    assert r.exit_code == 130, r.output
    work = tmp_path / "t.partial"
    assert "the finished trials (1) are kept in" in _said(r) and "--resume" in _said(r), _said(r)
    assert f"each file complete: {work / 'optuna.db'};" in _said(r)  # written, and said
    assert _files(out) == earlier

    r = _tune(out, "--trials", "4")
    assert r.exit_code == 2 and "--resume" in r.stderr  # a fresh run would drop the kept trials
    r = _tune(out, "--trials", "4", "--resume", "--seed", "3")  # the last --seed counts
    assert r.exit_code == 2 and "differs from this one in seed (it was run with 2)" in _said(r), _said(r)
    rerun = []
    monkeypatch.setattr(search, "evaluate", lambda task: rerun.append(1) or real(task))
    r = _tune(out, "--trials", "4", "--resume")
    assert r.exit_code == 0, r.output
    assert sorted(f.name for f in tmp_path.iterdir()) == ["t"]  # no DIR.partial, no old set aside
    resumed = _trials(out)
    assert len(resumed) == 4 and len(rerun) == 3  # trial 0 kept, not run again

    r = _tune(tmp_path / "u", "--trials", "4")
    assert r.exit_code == 0, r.output
    assert resumed == _trials(tmp_path / "u")


@pytest.mark.slow
def test_tune_failed_write_leaves_the_earlier_set(tmp_path, monkeypatch):
    """Disk full while the new set is written: DIR is the earlier set, whole; --resume writes it later
    without running a trial again."""
    import fte_casadi.plot as plot
    import fte_casadi.tune._search as search

    out = tmp_path / "t"
    r = _tune(out, "--trials", "2")
    assert r.exit_code == 0, r.output
    earlier = _files(out)

    def disk_full(*a, **k):
        raise OSError(28, "No space left on device")

    real_figure = plot.pareto_figure
    monkeypatch.setattr(plot, "pareto_figure", disk_full)
    r = _tune(out, "--trials", "3", "--seed", "5")
    assert r.exit_code == 2, r.output
    assert "No space left on device" in _said(r) and "--resume" in _said(r)
    assert _files(out) == earlier

    monkeypatch.setattr(plot, "pareto_figure", real_figure)
    monkeypatch.setattr(search, "evaluate", lambda task: pytest.fail("a kept trial was run again"))
    r = _tune(out, "--trials", "3", "--seed", "5", "--resume")
    assert r.exit_code == 0, r.output
    assert len(_trials(out)) == 3 and (out / "pareto.png").stat().st_size > 1000


@pytest.mark.slow
def test_tune_refuses_a_directory_with_other_files(tmp_path):
    out = tmp_path / "t"
    out.mkdir()
    (out / "notes.txt").write_text("mine")
    r = _tune(out, "--trials", "2")
    assert r.exit_code == 2 and "notes.txt" in _said(r) and "as a whole" in _said(r)
    assert (out / "notes.txt").read_text() == "mine"
    assert sorted(f.name for f in tmp_path.iterdir()) == ["t"]


# -- Ctrl-C always wins ---------------------------------------------------------------------
@pytest.mark.parametrize("then", ["goes on", "fails"])
def test_a_swallowed_ctrl_c_still_ends_with_130_and_writes_nothing(tmp_path, monkeypatch, then):
    """CasADi returns None from a call a Ctrl-C interrupted (the design then goes on, or fails later with an
    error of its own): the command still ends with 130, and the document is not written."""
    import fte_casadi.cli._design as cli_design
    from fte_casadi.design import Design

    def swallowing(*a, **k):
        try:
            os.kill(os.getpid(), signal.SIGINT)
            time.sleep(1.0)  # the handler runs at the next bytecode
        except KeyboardInterrupt:
            pass  # what CasADi and a retrying library do with it
        d = Design.load(ROOT / "generated" / "manipulator" / "design.json") if then == "goes on" else None
        return d, None, None

    monkeypatch.setattr(cli_design, "_make_design", swallowing)
    target = tmp_path / "d.json"
    r = CliRunner().invoke(main, ["design", "manipulator", "-o", str(target)])
    assert r.exit_code == 130, r.output
    assert "interrupted; nothing was written" in _said(r) and "internal error" not in r.output
    assert os.listdir(tmp_path) == []


def test_scs_catching_sigint_itself_is_a_ctrl_c():
    """SCS installs its own SIGINT handler while it solves and reports 'interrupted' as a failure (the design
    would then try the other solver): fte's SCS raises it as KeyboardInterrupt and records it."""
    import cvxpy as cp

    from fte_casadi import _interrupt
    from fte_casadi.design.core._sdp import cvxpy_solver

    n = 150
    X = cp.Variable((n, n), PSD=True)
    A = np.random.default_rng(0).normal(size=(n, n))
    prob = cp.Problem(cp.Minimize(cp.trace((A + A.T) @ X)), [cp.trace(X) == 1])
    timer = threading.Timer(0.5, lambda: os.kill(os.getpid(), signal.SIGINT))
    with _interrupt.handling():
        timer.start()
        with pytest.raises(KeyboardInterrupt) as caught:
            prob.solve(solver=cvxpy_solver("SCS"), max_iters=10**7, eps_abs=1e-15, eps_rel=1e-15)
        assert _interrupt.pending()
    assert any(
        f.name == "solve_via_data" for f in caught.traceback
    )  # from SCS's status, not Python's handler
    assert not _interrupt.pending()  # outside the command nothing is recorded


def test_ctrl_c_while_the_modules_load_is_one_line():
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    code = "import sys; sys.stderr.write('go\\n'); sys.stderr.flush(); import fte_casadi.cli"
    p = subprocess.Popen([sys.executable, "-c", code], cwd=ROOT, env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, preexec_fn=_interruptible)  # fmt: skip
    assert p.stderr.readline() == b"go\n"  # Python is up; fte_casadi's modules load now (about 2 s)
    time.sleep(0.2)
    p.send_signal(signal.SIGINT)
    _, err = p.communicate(timeout=120)
    assert p.returncode == 130, err
    assert err.decode().strip() == "fte: interrupted while loading; nothing was written"


@pytest.mark.slow
def test_sigint_at_any_moment_of_fte_design_ends_with_130(tmp_path):
    """SIGINT while the modules load, while the T-S model is derived and while the LMIs are solved: always
    status 130, one paragraph, and the document written only if the interrupt came after it was complete."""
    target = tmp_path / "d.json"
    # `fte design manipulator` takes 3.5-6 s here (the suite's calibration budget): loading ~1 s, deriving to ~2 s, solving
    for delay in (0.5, 1.5, 3.0):
        target.unlink(missing_ok=True)
        p = _fte("design", "manipulator", "-o", str(target))
        time.sleep(delay)
        alive = p.poll() is None
        p.send_signal(signal.SIGINT)  # polls first: a child that ended in between is not signalled
        sent = alive and p.returncode is None
        _, err = p.communicate(timeout=120)
        err = " ".join(err.decode().split())
        if not sent:  # the design was done before the signal (a fast machine)
            assert p.returncode == 0 and Design.load(target).certified, (delay, p.returncode, err)
            continue
        assert p.returncode in (130, -signal.SIGINT), (delay, p.returncode, err)
        assert "Traceback" not in err and "internal error" not in err, err
        if p.returncode == 130:
            assert "interrupted" in err
            assert target.exists() == ("written before the interrupt" in err), err


# -- fte codegen: its files as one set ----------------------------------------------------------
MANIP = ROOT / "generated" / "manipulator" / "design.json"


def test_codegen_replaces_its_files_as_one_set_and_keeps_the_rest(tmp_path, monkeypatch):
    from fte_casadi.codegen import generate_c
    from fte_casadi.design import Design

    d = Design.load(MANIP)
    out = tmp_path / "c"
    generate_c(d, out, sample_time=2e-3)
    (out / "main.c").write_text("int main(void) { return 0; }\n")
    (out / "lib").mkdir()
    (out / "lib" / "x.txt").write_text("mine")
    before = _files(out)
    inode = (out / "main.c").stat().st_ino
    real_open, opened = open, []

    def failing(path, *a, **k):  # the third new file fails to be written (a full disk)
        if str(path).startswith(str(tmp_path / ".c.new-")):
            opened.append(path)
            if len(opened) == 3:
                raise OSError(28, "No space left on device")
        return real_open(path, *a, **k)

    monkeypatch.setattr("builtins.open", failing)
    with pytest.raises(Exception, match="No space left on device"):
        generate_c(d, out)
    monkeypatch.undo()
    assert _files(out) == before and sorted(p.name for p in tmp_path.iterdir()) == ["c"]  # no mix, no debris
    files = generate_c(d, out)
    assert [f.name for f in files] == ["fte_manipulator.h", "fte_manipulator.c", "fte_manipulator_casadi.h",
                                       "fte_manipulator_casadi.c", "README.md"]  # fmt: skip
    assert (out / "main.c").stat().st_ino == inode and (out / "lib" / "x.txt").read_text() == "mine"
    assert _files(out) != before and sorted(p.name for p in tmp_path.iterdir()) == ["c"]


def test_a_mix_of_two_sets_does_not_compile(tmp_path):
    """Even without -Werror: each .c file checks the set's number of the headers it includes."""
    from fte_casadi.codegen import _build as build
    from fte_casadi.codegen import generate_c
    from fte_casadi.design import Design

    if build.find_compiler() is None:
        pytest.skip("no C compiler")
    d = Design.load(MANIP)
    generate_c(d, tmp_path / "a")
    generate_c(d, tmp_path / "b", sample_time=2e-3)
    for name in ("fte_manipulator_casadi.c", "fte_manipulator.h"):
        mixed = tmp_path / f"mix-{name}"
        mixed.mkdir()
        for f in (tmp_path / "a").glob("fte_*"):
            (mixed / f.name).write_bytes(((tmp_path / "b") if f.name == name else (tmp_path / "a")).joinpath(
                f.name).read_bytes())  # fmt: skip
        r = subprocess.run([build.find_compiler(), "-std=c99", "-c", *map(str, mixed.glob("*.c"))], cwd=mixed,
                           capture_output=True, text=True)  # fmt: skip
        assert r.returncode != 0 and "of another run of fte codegen" in r.stderr, r.stderr


def test_codegen_into_the_current_directory_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    r = CliRunner().invoke(main, ["codegen", str(MANIP), "--out", "."])
    assert r.exit_code == 2 and "replaces its output directory as one set" in _said(r), r.output
    assert os.listdir(tmp_path) == []


def test_the_printed_compile_line_builds_from_anywhere(tmp_path):
    """A directory with a space: the line quotes it and names it with -I for the header."""
    from fte_casadi.codegen import _build as build

    if build.find_compiler() is None:
        pytest.skip("no C compiler")
    out = tmp_path / "my c"
    r = CliRunner().invoke(main, ["codegen", str(MANIP), "--out", str(out)])
    assert r.exit_code == 0, r.output
    line = [x for x in r.stdout.splitlines() if x.startswith("compile with: ")][0][len("compile with: ") :]
    assert f"-I'{out}'" in line
    work = tmp_path / "elsewhere"
    work.mkdir()
    (work / "your_main.c").write_text('#include "fte_manipulator.h"\nint main(void) {\n  fte_manipulator_state s;\n'
                                      "  return fte_manipulator_init(&s, 0);\n}\n")  # fmt: skip
    r = subprocess.run(line + " -o prog", shell=True, cwd=work, capture_output=True, text=True)
    assert r.returncode == 0, r.stderr
    assert subprocess.run([str(work / "prog")]).returncode == 0


@pytest.mark.slow
def test_a_refused_resume_of_a_finished_run_leaves_no_partial_folder(tmp_path):
    """--resume of a finished run with another --seed is refused; the copy of its trials made for the run is
    removed, so that the next run is not taken for an interrupted one."""
    out = tmp_path / "t"
    r = _tune(out, "--trials", "2")
    assert r.exit_code == 0, r.output
    earlier = _files(out)
    r = _tune(out, "--trials", "3", "--resume", "--seed", "3")
    assert r.exit_code == 2 and "differs from this one in seed (it was run with 2)" in _said(r), _said(r)
    assert sorted(f.name for f in tmp_path.iterdir()) == ["t"] and _files(out) == earlier
    from fte_casadi.cli._tune import _tune_target

    _tune_target(str(out), resume=False)  # a fresh run is not refused as continuing an interrupted one
