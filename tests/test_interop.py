"""python-control interop (issue #12): local models and local closed loops."""

from __future__ import annotations

import numpy as np
import pytest

control = pytest.importorskip("control")


def _match(got, want) -> float:
    """Largest distance from a value of ``got`` to the nearest of ``want``, relative to max |want|."""
    return max(min(abs(g - w) for w in want) for g in got) / max(abs(want))


def test_each_rule_is_a_named_state_space_with_the_poles_of_A(ts_models):
    ts = ts_models["manipulator"]
    systems = ts.to_control()
    assert len(systems) == ts.r == 2
    for lm, sys in zip(ts.local_models, systems):
        assert sys.input_labels == ["u", "d", "fa", "fs"] and sys.output_labels == [
            "theta_m",
            "w_m",
            "theta_l",
        ]
        assert _match(control.poles(sys), np.linalg.eigvals(lm.A)) < 1e-12
        assert np.allclose(np.ravel(control.dcgain(sys[:, 0])), -ts.C @ np.linalg.solve(lm.A, lm.B[:, 0]))


@pytest.mark.parametrize("i, j", [(0, 0), (0, 1), (1, 0), (1, 1)])
def test_closed_loop_poles_are_controller_and_observer_poles(real_designs, ts_models, i, j):
    d = real_designs["manipulator"]
    lm = ts_models["manipulator"].local_models[i]
    cl = d.to_control(i, j)
    want = np.concatenate([np.linalg.eigvals(lm.A + lm.B @ d.K[j]), np.linalg.eigvals(d.R[i])])
    assert len(control.poles(cl)) == len(want)
    assert _match(control.poles(cl), want) < 1e-9
    assert cl.input_labels[:1] == ["u_ref"] and "fa_hat" in cl.output_labels


def test_sampled_closed_loop_is_stable_and_step_response_runs(real_designs):
    d = real_designs["three-tank"]
    cl = d.to_control(1, 1, sample_time=0.01)
    assert cl.dt == 0.01 and np.max(np.abs(control.poles(cl))) < 1
    resp = control.step_response(cl[0, 0], T=np.arange(0, 5, 0.01))
    assert np.all(np.isfinite(resp.outputs))


def test_bad_rule_index_is_refused(real_designs):
    from fte_casadi.errors import ParameterError

    with pytest.raises(ParameterError, match="rule index i"):
        real_designs["manipulator"].to_control(5, 0)


def test_missing_python_control_is_a_clear_error(monkeypatch, ts_models):
    import builtins

    from fte_casadi.errors import MissingDependencyError

    real_import = builtins.__import__

    def no_control(name, *a, **k):
        if name == "control":
            raise ImportError("no control")
        return real_import(name, *a, **k)

    monkeypatch.setattr(builtins, "__import__", no_control)
    with pytest.raises(MissingDependencyError, match=r"pip install 'fte_casadi\[control\]'"):
        ts_models["manipulator"].to_control()
