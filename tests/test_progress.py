"""Long work says what it is doing: a design's steps, its parameter search's trials and its diagnosis reach the
reporter in force (:mod:`fte_casadi._progress`), and ``fte design`` shows them on a terminal's status line."""

from __future__ import annotations

import io
import threading

from plant_kf_rules import plant, scenario

from fte_casadi._progress import SEPARATOR, note, reporting, stage
from fte_casadi.cli import _targets
from fte_casadi.design import design
from fte_casadi.ts import derive


def test_notes_name_the_stages_that_hold_them_and_nothing_is_left_behind():
    outer, inner = [], []
    note("before any reporter")  # nothing to tell: no error
    with reporting(outer.append):
        note("a")
        with stage("trial 1"):
            note("step 3")
            with reporting(inner.append):
                note("step 5")
            note("step 7")
        note("b")
    note("after")
    assert outer == ["a", "trial 1", f"trial 1{SEPARATOR}step 3", f"trial 1{SEPARATOR}step 7", "b"]
    assert inner == [f"trial 1{SEPARATOR}step 5"]


def test_another_thread_does_not_report_to_this_one():
    seen = []
    with reporting(seen.append):
        t = threading.Thread(target=note, args=("elsewhere",))
        t.start()
        t.join()
        note("here")
    assert seen == ["here"]


def test_a_design_whose_defaults_fail_reports_each_trial_and_the_steps_inside_it():
    """The generic sigma = 1 fails (45) on this plant; the search's first trial certifies (params_chosen)."""
    notes = []
    with reporting(notes.append):
        d = design(derive(plant()), sample_time=scenario().dt)
    assert d.certified and set(d.params_chosen) == {"sigma"}
    sigma = d.params.sigma
    assert notes[0].startswith("step 3: the gain K by LMI (45) at sigma = 1,")
    trials = [n for n in notes if n.startswith("parameter search, trial ") and SEPARATOR not in n]
    assert trials and trials[-1].startswith(
        f"parameter search, trial {len(trials)}: sigma = {sigma:g} (LMI (45)"
    )
    inside = [n.split(SEPARATOR)[1] for n in notes if n.startswith(trials[-1] + SEPARATOR)]
    assert inside[0].startswith(f"step 3: the gain K by LMI (45) at sigma = {sigma:.3g},")
    assert any(s.startswith(f"step 5: the observer by LMI (46) at sigma = {sigma:.3g},") for s in inside)


class _Terminal(io.StringIO):
    def isatty(self):
        return True


def test_the_status_line_shows_on_a_terminal_after_its_delay_and_never_elsewhere():
    times = iter([0.0, 0.5, 2.0])  # the start, then the time at each note
    term = _Terminal()
    with _targets._design_status("tank", term, clock=lambda: next(times)):
        note("step 3: early")
        note("step 5: late")
    shown = term.getvalue()
    assert "design tank [" in shown and "step 5: late" in shown and "step 3: early" not in shown
    piped = io.StringIO()
    with _targets._design_status("tank", piped):
        note("step 3")
    assert piped.getvalue() == ""
