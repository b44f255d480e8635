"""Figures: one per paper figure, written as readable PNG files."""

import numpy as np
import pytest
from matplotlib.figure import Figure

from fte_casadi.plot import figure_set, output_figure, state_figure, write_figures
from fte_casadi.sim import Bias, LossOfEffectiveness, Scenario, Stuck, UniformNoise, simulate


@pytest.fixture(scope="module")
def results(plants, lqr_designs):
    m = Scenario(
        name="m",
        T=1.0,
        dt=1e-3,
        faults=(LossOfEffectiveness("fa", 0.4, 0.25, 0.5), Stuck("fs", 0.7, 1.0)),
        unknown_input=UniformNoise(0.1),
        x0_noise=0.005,
    )
    t = Scenario(
        name="t",
        T=20.0,
        dt=1e-2,
        faults=(Bias("fa", -10.0, 5.0, 15.0),),
        unknown_input=UniformNoise(0.1),
        x0_noise=0.2,
    )
    return {
        "manipulator": simulate(
            lqr_designs["manipulator"], plants["manipulator"], m, paths=3, seed=1, progress=False
        ),
        "three-tank": simulate(
            lqr_designs["three-tank"], plants["three-tank"], t, paths=3, seed=1, progress=False
        ),
    }


@pytest.mark.slow
def test_manipulator_figures(results, tmp_path):
    paths = write_figures(results["manipulator"], tmp_path)
    names = [p.name for p in paths]
    assert names == [
        "fig02_theta_m.png",
        "fig03_w_m.png",
        "fig04_theta_l.png",
        "fig05_w_l.png",
        "fig06_fa.png",
        "fig07_fs.png",
        "fig08_theta_m.png",
        "fig09_w_m.png",
        "fig10_theta_l.png",
    ]
    for p in paths:
        assert p.stat().st_size > 10_000
        assert p.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


@pytest.mark.slow
def test_three_tank_figures(results, tmp_path):
    names = [p.name for p in write_figures(results["three-tank"], tmp_path)]
    assert names == [
        "fig11_h1.png",
        "fig12_h2.png",
        "fig13_h3.png",
        "fig14_fa.png",
        "fig15_h2_paths.png",
        "fig16_h2_means.png",
    ]


def test_figure_content(results):
    r = results["manipulator"]
    fig = state_figure(r, 0)
    assert isinstance(fig, Figure)
    ax = fig.axes[0]
    assert "Fig. 2" in ax.get_title() and ax.get_ylabel() == "theta_m [rad]" and ax.get_xlabel() == "time [s]"
    np.testing.assert_allclose(ax.lines[0].get_ydata(), r.ftc.x[:, :, 0].mean(axis=0))
    fig = output_figure(r, 2)
    labels = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert len(labels) == 3 and any("fault-free" in s for s in labels)
    assert len(figure_set(r)) == 9
