"""Every figure of `fte simulate`'s metrics document, recomputed from the recorded arrays.

Written from docs/interface.md ("The metrics document") and the FDI vocabulary only, without the
package's own metric code, so that a slip in one shows up as a disagreement with the other.
"""

from __future__ import annotations

import dataclasses
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
from scipy import stats

from fte_casadi.design import Design
from fte_casadi.plants import load_plant, load_scenario
from fte_casadi.sim import Bias, simulate
from fte_casadi.step import step_function

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
    # noise on w_m of 2.5 rad/s against the +/- 6 its generated C accepts: some readings it would refuse
    "manipulator-refused": dict(
        spec="manipulator", design="manipulator", T=None, paths=3, seed=19, noise=(0.05, 2.5, 0.05)
    ),  # fmt: skip
    # two more windows of the sensor fault, of other sizes, one of them inside the actuator fault's window: each
    # window's own peak, and the figures of overlapping windows
    "manipulator-windows": dict(
        spec="manipulator",
        design="manipulator",
        T=None,
        paths=3,
        seed=23,
        extra=(Bias("fs", 0.01, start=1.0, stop=2.0), Bias("fs", 0.005, start=3.0, stop=4.0)),
    ),  # fmt: skip
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
    if case.get("extra"):
        scenario = dataclasses.replace(scenario, faults=scenario.faults + case["extra"])
    run = dict(paths=case["paths"], seed=case["seed"], record_all=True, record_every=1, progress=False)
    if isinstance(case.get("noise"), tuple):
        scenario = dataclasses.replace(scenario, measurement_noise=case["noise"])
    elif case.get("noise"):  # 1 % of each output's span on a noise-free run
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


def uncompensated(res, mask):
    """The inputs the step without tolerant control computes at the FTC run's samples ``mask``: at its observer
    state ``z = xbarhat - H y`` (a gate's latches and memory, which it does not read, zero) and measurement."""
    d, ftc = res.design, res.ftc
    fn = step_function(d, res.dt, tolerant=False)
    P, S = ftc.y[:, mask].shape[:2]
    y = ftc.y[:, mask].reshape(P * S, -1)
    z = ftc.xbarhat[:, mask].reshape(P * S, -1) - y @ np.asarray(d.H).T
    z = np.hstack([z, np.zeros((P * S, d.nz - z.shape[1]))])
    u = np.asarray(fn.map(P * S)(z.T, y.T)[1]).T
    return u.reshape(P, S, -1)


def rms(v):
    return float(np.sqrt(np.mean(np.square(v))))


def outside_mask(res, j, transient, settle_after):
    """Samples outside fault j: after the transient, outside j's windows and their lag."""
    t, m = res.t, res.t >= transient
    for jj, _, a, b in windows(res):
        if jj == j:
            m &= ~between(t, a, b) & ~between(t, b, b + settle_after)
    return m


def thresholds_at(entry, t):
    """A fault's threshold at each sample: a start-up block's own in [start, stop), else the steady one."""
    thr = np.full(t.size, float(entry["threshold"]))
    for b in entry["startup_thresholds"]:
        thr[(t >= b["start"]) & (t < b["stop"])] = b["threshold"]
    return thr


def alarm_run(r, thr, after):
    """Per path the samples where the alarm is raised and its state before each sample: off until ``after``,
    on at r >= thr, off at r < thr / 2 (the thresholds of each sample)."""
    raised = np.zeros(r.shape, bool)
    before = np.zeros(r.shape, bool)
    for p, rp in enumerate(r):
        on = False
        for k, v in enumerate(rp):
            before[p, k] = on
            if not after[k]:
                on = False
            elif not on and v >= thr[k]:
                on = raised[p, k] = True
            elif on and v < 0.5 * thr[k]:
                on = False
    return raised, before


def replicates(seed, a, b):
    """The documented bootstrap over the paths of (sum a, sum b): the pairs sorted by (a, b), then Poisson(1)
    weights (paths x 1000) of default_rng([seed, 39]), path by path in that order."""
    order = np.lexsort((b, a))
    W = np.random.default_rng([seed, 39]).poisson(1.0, (len(a), 1000)).astype(float)
    return W.T @ np.asarray(a, float)[order], W.T @ np.asarray(b, float)[order]


def percentiles(v):
    return list(np.percentile(v, [2.5, 97.5])) if v.size >= 500 else None


def ratio_interval(seed, a, b):
    """The 95 % interval of sqrt(sum a / sum b) over the paths."""
    num, den = replicates(seed, a, b)
    return percentiles(np.sqrt(num[den > 0] / den[den > 0]))


def rate_interval(seed, counts, exposure):
    """Garwood's exact interval of the total count, widened where the bootstrap over the paths is wider."""
    k, total = int(np.sum(counts)), exposure * len(counts)
    lo = 0.0 if k == 0 else stats.chi2.ppf(0.025, 2 * k) / 2
    hi = stats.chi2.ppf(0.975, 2 * k + 2) / 2
    num, den = replicates(seed, counts, np.full(len(counts), exposure))
    b = percentiles(num[den > 0] / den[den > 0]) or [np.inf, -np.inf]
    return [min(lo / total, b[0]), max(hi / total, b[1])]


def clopper_pearson(k, n):
    lo = 0.0 if k == 0 else stats.beta.ppf(0.025, k, n - k + 1)
    hi = 1.0 if k == n else stats.beta.ppf(0.975, k + 1, n - k)
    return [lo, hi]


def per_path(v):
    return np.sum(np.square(v), axis=tuple(range(1, v.ndim)))


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
        want = (
            None
            if zero
            else ratio_interval(res.seed, per_path(fh[:, whole] - f[:, whole]), per_path(f[:, whole]))
        )
        check(f"fault_rel_rms_error_interval[{name}]", doc["fault_rel_rms_error_interval"][j], want)
        # the allowances' own peaks: before the transient, and within settle_after of a window's end (after it)
        lag = np.zeros(t.size, bool)
        for jj, _, _a, b in ws:
            lag |= between(t, b, b + settle_after) if jj == j else False
        parts = {
            "": out,
            "_startup": ~whole & (t < transient),
            "_after_window": ~whole & (t >= transient) & lag,
        }
        peaks = {}
        for tag, m in parts.items():
            if not zero and m.any():
                q, k = np.unravel_index(np.argmax(np.abs(fh[:, m])), fh[:, m].shape)
                peaks[tag] = (
                    np.abs(fh[:, m]).max() / np.abs(f[:, whole]).max(),
                    t[m][k],
                    fh[:, m][q, k] / np.abs(f[:, whole]).max(),
                )
        for tag in ("_startup", "_after_window"):
            check(
                f"false_alarm_peak{tag}[{name}]",
                doc[f"false_alarm_peak{tag}"][j],
                peaks[tag][0] if tag in peaks else None,
            )
        top = max(peaks.values(), key=lambda v: v[0]) if peaks else None
        check(f"false_alarm_peak_raw[{name}]", doc["false_alarm_peak_raw"][j], top[0] if top else None)
        for key, v in (("false_alarm_peak_at", peaks.get("")), ("false_alarm_peak_raw_at", top)):
            got = doc[key][j]
            check(
                f"{key}[{name}]",
                None if got is None else [got["t"], got["value"]],
                None if v is None else v[1:],
            )
    union = np.zeros(t.size, bool)
    for *_, a, b in ws:
        union |= between(t, a, b)
    C = np.asarray(res.design.C)
    cx = {run: r.x[:, union] @ C.T for run, r in (("free", free), ("noftc", noftc), ("ftc", ftc))}
    check("ftc_true_ratio", doc["ftc_true_ratio"], ratio(cx["ftc"] - cx["free"], cx["noftc"] - cx["free"]))
    y0 = free.y[:, union]
    want = ratio(ftc.yc[:, union] - y0, noftc.y[:, union] - y0)
    check("ftc_compensated_ratio", doc["ftc_compensated_ratio"], want)
    want = ratio_interval(res.seed, per_path(cx["ftc"] - cx["free"]), per_path(cx["noftc"] - cx["free"]))
    check("ftc_true_ratio_interval", doc["ftc_true_ratio_interval"], want)
    want = ratio_interval(res.seed, per_path(ftc.yc[:, union] - y0), per_path(noftc.y[:, union] - y0))
    check("ftc_compensated_ratio_interval", doc["ftc_compensated_ratio_interval"], want)
    if res.region is None:
        check("outside_region", doc["outside_region"], 0.0)
    else:
        lo, hi = (np.asarray(v, dtype=float) for v in res.region)
        out = np.zeros(ftc.x.shape[:2], bool)
        for r in (free, noftc, ftc):
            out |= np.any((r.x < lo) | (r.x > hi), axis=-1)
        check("outside_region", doc["outside_region"], out.mean())
        assert doc["region"] == {"lo": [v if np.isfinite(v) else None for v in lo.tolist()],
                                 "hi": [v if np.isfinite(v) else None for v in hi.tolist()]}  # fmt: skip
    # where the plant ran: each state's extremes over the three runs, every path and sample
    every = np.concatenate([free.x, noftc.x, ftc.x], axis=0)
    check("state_range.lo", doc["state_range"]["lo"], every.min(axis=(0, 1)), exact=True)
    check("state_range.hi", doc["state_range"]["hi"], every.max(axis=(0, 1)), exact=True)
    check("input_saturation", doc["input_saturation"], at_limit(res, ftc.u).mean(axis=(0, 1)))
    _check_c_range(res, doc, check)
    check.done()


def accepted_by_the_c(res):
    """The range of y the committed generated C of the case's design accepts (its Y_MIN, Y_MAX arrays, read from
    the C source), or None for a design without committed C."""
    import re

    name = res.design.plant.replace("-", "_")
    src = ROOT / "generated" / name / f"fte_{name}.c"
    if not src.exists():
        return None
    text = src.read_text()
    out = []
    for side in ("MIN", "MAX"):
        body = re.search(rf"_Y_{side}\[\d+\] = \{{([^}}]*)\}}", text).group(1)
        out.append(np.array([float(v) for v in body.replace("\n", " ").split(",") if v.strip()]))
    return out


def _check_c_range(res, doc, check):
    """The FTC run's measurements the generated C would refuse: per output and in all, of the samples, of the
    paths, and the first time; the range against the committed C's own (built-in designs)."""
    rng = doc["c_accepted_range"]
    lo, hi = np.asarray(rng["lo"], float), np.asarray(rng["hi"], float)
    committed = accepted_by_the_c(res)
    if committed is not None:  # the built-in cases run the committed designs
        check("c_accepted_range.lo", lo, committed[0])
        check("c_accepted_range.hi", hi, committed[1])
    elif res.design.plant != "pendulum":
        check.errors.append(f"no committed C for {res.design.plant}")
    out = (res.ftc.y < lo) | (res.ftc.y > hi)
    hit = out.any(axis=-1)
    noise = getattr(res.scenario.measurement_noise, "std", None)  # white noise of these deviations
    if noise is not None and np.any(np.asarray(noise, float) >= 0.2 * (hi - lo)):
        # noise of a fifth of the range's width: half the width is at most 2.5 standard deviations away
        assert doc["outside_c_range"] > 0 and doc["outside_c_range_paths"] == 1.0
    check("outside_c_range", doc["outside_c_range"], hit.mean())
    check("outside_c_range_per_output", doc["outside_c_range_per_output"], out.mean(axis=(0, 1)))
    check("outside_c_range_paths", doc["outside_c_range_paths"], hit.any(axis=1).mean())
    firsts = [res.t[np.argmax(h)] for h in hit if h.any()]
    check("outside_c_range_first", doc["outside_c_range_first"], min(firsts) if firsts else None)


def test_windows(res):
    doc, check, t, ftc = res.metrics, Checker(), res.t, res.ftc
    thresholds = {d["fault"]: d for d in doc["detection"]}
    ws = windows(res)
    assert [(w["fault"], w["start"], w["stop"]) for w in doc["windows"]] == [(n, a, b) for _, n, a, b in ws]
    C = np.asarray(res.design.C)
    for w, (j, name, a, b) in zip(doc["windows"], ws):
        key = f"windows[{name} {a}-{b}]"
        inw, settled = between(t, a, b), between(t, a + 0.2 * (b - a), b)
        fh, f = ftc.fhat[..., j], ftc.f[..., j]
        zero = not np.any(f[:, inw])
        check(f"{key}.fault_peak", w["fault_peak"], np.abs(f[:, inw]).max())
        # the fault as each output reads it, for a fault that enters the measurement only
        Df = np.asarray(res.design.Df)
        in_state = any(
            np.any(np.asarray(getattr(lm, k))[:, j]) for lm in res.design.local_models for k in ("Bf", "Gf")
        )
        read = (0.0 if in_state else 1.0) * np.abs(Df[:, j]) * np.abs(f[:, inw]).max()
        check(f"{key}.sensor_fault_peak_per_output", w["sensor_fault_peak_per_output"], read)
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
        # the compensation applied: u less the step without tolerant control at the same z = xbarhat - H y and y
        u_none = uncompensated(res, inw)
        check(f"{key}.ftc_compensation_rms", w["ftc_compensation_rms"],
              np.sqrt(np.mean(np.square(ftc.u[:, inw] - u_none), axis=(0, 1))))  # fmt: skip
        k0 = np.flatnonzero(inw)[0]
        for run, x in (("ftc", ftc.x), ("no_ftc", res.no_ftc.x)):
            dev = (x[:, k0] - res.free.x[:, k0]) @ C.T
            check(f"{key}.onset_deviation.{run}", w["onset_deviation"][run], rms(np.linalg.norm(dev, axis=1)))
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
        seed = res.seed
        if not zero:
            want = ratio_interval(seed, per_path(fh[:, inw] - f[:, inw]), per_path(f[:, inw]))
            check(f"{key}.fault_rel_rms_error_interval", w["fault_rel_rms_error_interval"], want)
            check(
                f"{key}.ftc_true_ratio_interval",
                w["ftc_true_ratio_interval"],
                ratio_interval(seed, per_path(d_ftc), per_path(d_no)),
            )
            for i in range(C.shape[0]):
                want = ratio_interval(seed, per_path(d_ftc[..., i]), per_path(d_no[..., i]))
                check(
                    f"{key}.ftc_true_ratio_per_output_interval[{i}]",
                    w["ftc_true_ratio_per_output_interval"][i],
                    want,
                )
        if name not in thresholds:
            assert w["detection_delay"] is None and w["missed_detections"] is None, key
            continue
        # the alarm rule at each sample's threshold; a path whose alarm is on at the onset is a standing alarm
        after = t >= doc["transient"]
        raised, before = alarm_run(np.abs(fh), thresholds_at(thresholds[name], t), after)
        k0 = np.flatnonzero(inw)[0]
        standing = before[:, k0]
        delays = [t[inw][np.argmax(r)] - a for r, st in zip(raised[:, inw], standing) if r.any() and not st]
        P = fh.shape[0]
        check(f"{key}.detection_delay", w["detection_delay"], np.mean(delays) if delays else None)
        check(
            f"{key}.detection_delay_max",
            w["detection_delay_max"],
            max(delays) if delays else None,
            exact=True,
        )
        check(f"{key}.standing_alarm_paths", w["standing_alarm_paths"], int(standing.sum()), exact=True)
        check(
            f"{key}.missed_detections",
            w["missed_detections"],
            P - int(standing.sum()) - len(delays),
            exact=True,
        )
        check(f"{key}.detection_probability", w["detection_probability"], len(delays) / P)
        check(
            f"{key}.detection_probability_interval",
            w["detection_probability_interval"],
            clopper_pearson(len(delays), P),
        )
        allowed = min(3.0 * doc["observer_time_constant"], b - a)
        check(f"{key}.detection_delay_allowed", w["detection_delay_allowed"], allowed)
        within = sum(1 for v in delays if v <= allowed + 1e-9)
        check(f"{key}.detection_probability_within", w["detection_probability_within"], within / P)
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
    P = res.free.x.shape[0]
    tau = doc["observer_time_constant"]
    for j, d in enumerate(doc["detection"]):
        thr, key = thresholds_at(d, t), f"detection[{d['fault']}]"
        assert np.all(np.isfinite(thr)) and np.all(thr >= d["threshold"]) and d["threshold"] > 0, key
        # calibration: paths P, P + 1, ... for N = 25 expected alarms per block of one observer time constant
        # (at least 200, at most the budget of path-steps, but at least 16), their fault-free time after the transient
        steps = round(res.scenario.T / res.dt)
        block = max(1, round(max(tau, res.scenario.T / 128) / res.dt)) * res.dt
        budget = float(os.environ.get("FTE_CALIBRATION_BUDGET", 2e7))  # path-steps per pass (conftest.py)
        want = min(
            max(int(np.ceil(25 / (d["false_alarm_rate_asked"] * block))), 200), max(16, int(budget // steps))
        )
        check(f"{key}.calibration_paths", d["calibration_paths"], want, exact=True)
        check(f"{key}.calibration_first_path", d["calibration_first_path"], P, exact=True)
        check(f"{key}.calibration_time", d["calibration_time"], want * (res.scenario.T - transient))
        lo, hi = d["false_alarm_rate_interval"]
        assert lo <= d["false_alarm_rate_calibration"] <= hi and d["false_alarm_count_calibration"] >= 0, key
        assert all(
            b["start"] >= transient - 1e-12 and b["stop"] <= d["steady_from"] + 1e-9
            for b in d["startup_thresholds"]
        )
        per_hour = {"s": 3600.0, "min": 60.0, "h": 1.0}.get(res.names["time_unit"])
        if per_hour is not None:  # the default: one false alarm per hour of operation
            check(f"{key}.false_alarm_rate_asked", d["false_alarm_rate_asked"], 1.0 / per_hour)
        after = t >= transient
        raised, _ = alarm_run(np.abs(res.free.fhat[..., j]), thr, after)
        n = raised[:, after].sum(axis=1)
        check(f"{key}.false_alarm_rate", d["false_alarm_rate"], n.sum() / (after.sum() * P * res.dt))
        check(f"{key}.false_alarm_count", d["false_alarm_count"], int(n.sum()), exact=True)
        check(f"{key}.false_alarm_rate_measured_interval", d["false_alarm_rate_measured_interval"],
              rate_interval(res.seed, n, after.sum() * res.dt))  # fmt: skip
        out = outside_mask(res, j, transient, settle_after)
        raised, _ = alarm_run(np.abs(res.ftc.fhat[..., j]), thr, after)
        n = raised[:, out].sum(axis=1)
        want = None if not out.any() else n.sum() / (out.sum() * P * res.dt)
        check(f"{key}.false_alarm_rate_ftc_run", d["false_alarm_rate_ftc_run"], want)
        if out.any():
            check(f"{key}.false_alarm_rate_ftc_run_interval", d["false_alarm_rate_ftc_run_interval"],
                  rate_interval(res.seed, n, out.sum() * res.dt))  # fmt: skip
    check.done()
