"""Every figure of `fte simulate`'s metrics document, recomputed from the recorded arrays.

Written from docs/interface.md ("The metrics document") and the FDI vocabulary only, without the
package's own metric code, so that a slip in one shows up as a disagreement with the other.
"""

from __future__ import annotations

import dataclasses
import subprocess
from pathlib import Path

import numpy as np
import pytest

from fte_casadi.design import Design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import simulate

pytestmark = pytest.mark.slow

ROOT = Path(__file__).resolve().parents[1]
PENDULUM = f"{ROOT / 'examples' / 'pendulum_plant.py'}:pendulum"
REL, ABS = 1e-9, 1e-12
# case: plant spec, committed design (None: designed here), shortened horizon, paths, seed, and
# optionally measurement noise (1 % of each output's span) or tighter input limits (to saturate)
CASES = {
    "manipulator": dict(spec="manipulator", design="manipulator", T=None, paths=4, seed=3),
    "three-tank": dict(spec="three-tank", design="three_tank", T=450.0, paths=3, seed=5),
    "quadruple-tank": dict(spec="quadruple-tank", design="quadruple_tank", T=700.0, paths=3, seed=7),
    "pendulum": dict(spec=PENDULUM, design=None, T=12.0, paths=4, seed=11),
    "manipulator-noise": dict(spec="manipulator", design="manipulator", T=None, paths=4, seed=13, noise=True),
    "quadruple-tank-limits": dict(
        spec="quadruple-tank",
        design="quadruple_tank",
        T=700.0,
        paths=3,
        seed=17,
        limits=[[-3, 1.2], [-0.03, 7]],
    ),
}


@pytest.fixture(scope="module")
def pendulum_design(tmp_path_factory):
    out = tmp_path_factory.mktemp("pendulum") / "design.json"
    subprocess.run(["fte", "design", PENDULUM, "-o", str(out)], check=True, capture_output=True)
    return Design.load(out)


@pytest.fixture(scope="module", params=list(CASES))
def res(request):
    case = CASES[request.param]
    plant, scenario = load_plant(case["spec"]), load_scenario(case["spec"])
    if case["design"] is None:
        design = request.getfixturevalue("pendulum_design")
    else:
        design = Design.load(ROOT / "generated" / case["design"] / "design.json")
    if case.get("limits") is not None:
        design = dataclasses.replace(design, input_limits=np.asarray(case["limits"], dtype=float))
    if case["T"] is not None:
        scenario = dataclasses.replace(scenario, T=case["T"])
    run = dict(paths=case["paths"], seed=case["seed"], record_all=True, record_every=1, progress=False)
    if case.get("noise"):  # 1 % of each output's span on a noise-free run
        span = np.ptp(simulate(design, plant, scenario, **run).free.y, axis=(0, 1))
        scenario = dataclasses.replace(scenario, measurement_noise=tuple(float(s) for s in 0.01 * span))
    return simulate(design, plant, scenario, **run)


class Checker:
    """Collects every disagreement, so that one run reports all of them."""

    def __init__(self):
        self.errors: list[str] = []

    def __call__(self, key, got, want, exact=False):
        if want is None or got is None:
            if got is not want:
                self.errors.append(f"{key}: package {got!r}, recomputed {want!r}")
            return
        want = np.asarray(want, dtype=float)
        got_a = np.asarray(got, dtype=float)
        ok = got_a.shape == want.shape and (
            np.array_equal(got_a, want) if exact else np.allclose(got_a, want, rtol=REL, atol=ABS)
        )
        if not ok:
            self.errors.append(f"{key}: package {got!r}, recomputed {want.tolist()!r}")

    def done(self):
        assert not self.errors, "\n".join(self.errors)


def windows(res):
    """(fault index, name, a, b) per fault window, in the scenario's order."""
    names = list(res.names["faults"])
    return [(names.index(w.fault), w.fault, w.start, w.stop) for w in res.scenario.faults]


def allowances(res):
    tau = 1.0 / abs(max(np.linalg.eigvals(np.asarray(R)).real.max() for R in res.design.R))
    ws = windows(res)
    transient = min(3 * tau, 0.5 * min(a for *_, a, _ in ws), 0.25 * res.scenario.T)
    settle_after = min(3 * tau, 0.25 * min(b - a for *_, a, b in ws))
    return transient, settle_after


def between(t, a, b):
    return (t >= a) & (t < b)


def ratio(num, den):
    """sqrt(sum num^2 / sum den^2); None when the denominator vanishes."""
    d = float(np.sum(np.square(den)))
    return None if d == 0.0 else float(np.sqrt(np.sum(np.square(num)) / d))


def rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


def outside_mask(res, j, transient, settle_after):
    """Samples outside fault j: after the transient, outside j's windows and their lag."""
    t, m = res.t, res.t >= transient
    for jj, _, a, b in windows(res):
        if jj == j:
            m &= ~between(t, a, b) & ~between(t, b, b + settle_after)
    return m


def raises(r, thr, mask):
    """Alarms raised at the samples in ``mask``: on at r >= thr, off at r < thr / 2 (per path)."""
    count = 0
    for rp in r:
        on = False
        for k, v in enumerate(rp):
            if not on and v >= thr:
                on = True
                count += bool(mask[k])
            elif on and v < 0.5 * thr:
                on = False
    return count


def first_from(E, limit, idx):
    """First index of ``idx`` from which E <= limit up to its last; None when E > limit at the end."""
    if idx.size == 0 or E[idx[-1]] > limit:
        return None
    bad = np.flatnonzero(E[idx] > limit)
    return idx[0] if bad.size == 0 else idx[bad[-1] + 1]


def at_limit(res, u):
    lim = res.design.input_limits
    if lim is None:
        return np.zeros(u.shape, dtype=bool)
    lim = np.asarray(lim, dtype=float)
    return (u <= lim[:, 0]) | (u >= lim[:, 1])


def test_run_and_allowances(res):
    doc, check = res.metrics, Checker()
    check("paths", doc["paths"], res.ftc.x.shape[0], exact=True)
    check("dt", doc["dt"], res.dt, exact=True)
    check("T", doc["T"], res.scenario.T, exact=True)
    check("seed", doc["seed"], res.seed, exact=True)
    assert doc["exact"] is True and doc["wall_s"] > 0
    change = doc["dt_change"]
    assert change is None or (set(change) >= {"from", "to", "why"} and change["to"] == res.dt), change
    np.testing.assert_allclose(res.t, np.arange(res.t.size) * res.dt, rtol=0, atol=1e-9 * res.scenario.T)
    assert res.t[-1] == pytest.approx(res.scenario.T)
    transient, settle_after = allowances(res)
    check("transient", doc["transient"], transient)
    check("settle_after", doc["settle_after"], settle_after)
    noise = res.scenario.measurement_noise  # a GaussianNoise model: one standard deviation per output
    noise = None if noise is None else list(noise.std)
    check("measurement_noise", doc["measurement_noise"], noise)
    if noise is not None:  # the noise is really on y, and only there
        e = res.free.y - res.free.x @ np.asarray(res.design.C).T
        np.testing.assert_allclose(e.std(axis=(0, 1)), noise, rtol=0.1)
    yc = res.ftc.y - res.ftc.fhat @ np.asarray(res.design.Df).T
    np.testing.assert_allclose(res.ftc.yc, yc, rtol=1e-9, atol=1e-12)
    check.done()


def test_global_figures(res):
    doc, check, t = res.metrics, Checker(), res.t
    transient, settle_after = doc["transient"], doc["settle_after"]
    free, noftc, ftc = res.free, res.no_ftc, res.ftc
    after = t >= transient
    err = ftc.x[:, after] - ftc.xhat[:, after]
    check("state_rms_error", doc["state_rms_error"], np.sqrt(np.mean(err**2, axis=1)).mean(axis=0))
    ws = windows(res)
    for j, name in enumerate(res.names["faults"]):
        whole = np.zeros(t.size, bool)
        settled = np.zeros(t.size, bool)
        for jj, _, a, b in ws:
            if jj == j:
                whole |= between(t, a, b)
                settled |= between(t, a + 0.2 * (b - a), b)
        fh, f = ftc.fhat[..., j], ftc.f[..., j]
        zero = not np.any(f[:, whole])
        want = None if zero else ratio(fh[:, whole] - f[:, whole], f[:, whole])
        check(f"fault_rel_rms_error[{name}]", doc["fault_rel_rms_error"][j], want)
        want = None if zero else ratio(fh[:, settled] - f[:, settled], f[:, settled])
        check(f"fault_rel_rms_error_settled[{name}]", doc["fault_rel_rms_error_settled"][j], want)
        out = outside_mask(res, j, transient, settle_after)
        none = zero or not out.any()
        peak = None if none else np.abs(fh[:, out]).max() / np.abs(f[:, whole]).max()
        check(f"false_alarm_peak[{name}]", doc["false_alarm_peak"][j], peak)
        rel = None if none else rms(fh[:, out]) / rms(f[:, whole])
        check(f"false_alarm_rel_rms[{name}]", doc["false_alarm_rel_rms"][j], rel)
    union = np.zeros(t.size, bool)
    for *_, a, b in ws:
        union |= between(t, a, b)
    C = np.asarray(res.design.C)
    cx = {run: r.x[:, union] @ C.T for run, r in (("free", free), ("noftc", noftc), ("ftc", ftc))}
    check("ftc_true_ratio", doc["ftc_true_ratio"], ratio(cx["ftc"] - cx["free"], cx["noftc"] - cx["free"]))
    y0 = free.y[:, union]
    want = ratio(ftc.yc[:, union] - y0, noftc.y[:, union] - y0)
    check("ftc_compensated_ratio", doc["ftc_compensated_ratio"], want)
    if res.region is None:
        check("outside_region", doc["outside_region"], 0.0)
    else:
        lo, hi = (np.asarray(v, dtype=float) for v in res.region)
        out = np.zeros(ftc.x.shape[:2], bool)
        for r in (free, noftc, ftc):
            out |= np.any((r.x < lo) | (r.x > hi), axis=-1)
        check("outside_region", doc["outside_region"], out.mean())
    check("input_saturation", doc["input_saturation"], at_limit(res, ftc.u).mean(axis=(0, 1)))
    check.done()


def test_windows(res):
    doc, check, t, ftc = res.metrics, Checker(), res.t, res.ftc
    thresholds = {d["fault"]: d["threshold"] for d in doc["detection"]}
    ws = windows(res)
    assert [(w["fault"], w["start"], w["stop"]) for w in doc["windows"]] == [(n, a, b) for _, n, a, b in ws]
    C = np.asarray(res.design.C)
    for w, (j, name, a, b) in zip(doc["windows"], ws):
        key = f"windows[{name} {a}-{b}]"
        inw, settled = between(t, a, b), between(t, a + 0.2 * (b - a), b)
        fh, f = ftc.fhat[..., j], ftc.f[..., j]
        zero = not np.any(f[:, inw])
        check(f"{key}.fault_peak", w["fault_peak"], np.abs(f[:, inw]).max())
        want = None if zero else ratio(fh[:, inw] - f[:, inw], f[:, inw])
        check(f"{key}.fault_rel_rms_error", w["fault_rel_rms_error"], want)
        want = None if zero else ratio(fh[:, settled] - f[:, settled], f[:, settled])
        check(f"{key}.fault_rel_rms_error_settled", w["fault_rel_rms_error_settled"], want)
        d_ftc = (ftc.x[:, inw] - res.free.x[:, inw]) @ C.T
        d_no = (res.no_ftc.x[:, inw] - res.free.x[:, inw]) @ C.T
        check(f"{key}.ftc_true_ratio", w["ftc_true_ratio"], None if zero else ratio(d_ftc, d_no))
        per = [ratio(d_ftc[..., i], d_no[..., i]) for i in range(C.shape[0])]
        got = w["ftc_true_ratio_per_output"]
        if zero:
            assert got is None or all(g is None for g in got), key
        else:
            for i, want in enumerate(per):
                check(f"{key}.ftc_true_ratio_per_output[{i}]", got[i], want)
        y0 = res.free.y[:, inw]
        want = None if zero else ratio(ftc.yc[:, inw] - y0, res.no_ftc.y[:, inw] - y0)
        check(f"{key}.ftc_compensated_ratio", w["ftc_compensated_ratio"], want)
        # settling after a, release after b, both on the path-mean error against the window's size
        E = np.abs(fh - f).mean(axis=0)
        limit = 0.1 * np.abs(f[:, inw]).mean(axis=0).max()
        k = first_from(E, limit, np.flatnonzero(inw))
        check(f"{key}.settling_time", w["settling_time"], None if k is None else t[k] - a, exact=True)
        nxt = min([s for *_, s, _ in ws if s >= b], default=None)
        after = (t >= b) & ((t < nxt) if nxt is not None else (t <= res.scenario.T))
        k = first_from(E, limit, np.flatnonzero(after))
        check(f"{key}.release_time", w["release_time"], None if k is None else t[k] - b, exact=True)
        check(
            f"{key}.input_saturation", w["input_saturation"], at_limit(res, ftc.u[:, inw]).mean(axis=(0, 1))
        )
        if name not in thresholds:
            assert w["detection_delay"] is None and w["missed_detections"] is None, key
            continue
        hit = np.abs(fh[:, inw]) >= thresholds[name]
        delays = [t[inw][np.argmax(h)] - a for h in hit if h.any()]
        check(f"{key}.detection_delay", w["detection_delay"], np.mean(delays) if delays else None)
        check(
            f"{key}.detection_delay_max",
            w["detection_delay_max"],
            max(delays) if delays else None,
            exact=True,
        )
        check(f"{key}.missed_detections", w["missed_detections"], hit.shape[0] - len(delays), exact=True)
    check.done()


def test_null_figures_say_why(res):
    """`why`: why a figure of the window is null, or null."""
    for w in res.metrics["windows"]:
        nulls = [k for k, v in w.items() if v is None and k != "why"]
        said = isinstance(w["why"], str) and bool(w["why"])
        assert said or not nulls, (
            f"window {w['fault']} {w['start']}-{w['stop']}: {nulls} null, why {w['why']!r}"
        )


def test_detection(res):
    doc, check, t = res.metrics, Checker(), res.t
    transient, settle_after = doc["transient"], doc["settle_after"]
    assert [d["fault"] for d in doc["detection"]] == list(res.names["faults"])
    for j, d in enumerate(doc["detection"]):
        thr, key = d["threshold"], f"detection[{d['fault']}]"
        assert np.isfinite(thr) and thr > 0, key
        assert d["calibration_paths"] == max(res.ftc.x.shape[0], 8), key
        assert d["calibration_peak_max"] > 0, key
        per_hour = {"s": 3600.0, "min": 60.0, "h": 1.0}.get(res.names["time_unit"])
        if per_hour is not None:  # the default: one false alarm per hour of operation
            check(f"{key}.false_alarm_rate_asked", d["false_alarm_rate_asked"], 1.0 / per_hour)
        after = t >= transient
        n = raises(np.abs(res.free.fhat[..., j]), thr, after)
        check(
            f"{key}.false_alarm_rate", d["false_alarm_rate"], n / (after.sum() * res.free.x.shape[0] * res.dt)
        )
        out = outside_mask(res, j, transient, settle_after)
        n = raises(np.abs(res.ftc.fhat[..., j]), thr, out)
        want = None if not out.any() else n / (out.sum() * res.ftc.x.shape[0] * res.dt)
        check(f"{key}.false_alarm_rate_ftc_run", d["false_alarm_rate_ftc_run"], want)
    check.done()
