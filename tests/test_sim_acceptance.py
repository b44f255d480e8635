"""Acceptance: the README's figures of the built-in designs, by the README's command.

README ("What `fte simulate` tells you") prints `fte simulate PLANT --paths 20 --seed 1` for the
committed designs. The same run here must give the same figures: the engine is deterministic
(IEEE, no contraction, the counter-based generator), so the only latitude is the C library's
transcendental functions, which differ between machines in the last bits; MARGIN allows 5 % on each
printed figure, far above that and far below a change of the design or of the definitions.
"""

from pathlib import Path

import pytest

from fte_casadi.design import Design
from fte_casadi.plants import SCENARIOS, load_plant
from fte_casadi.sim import simulate

GENERATED = Path(__file__).resolve().parents[1] / "generated"

MARGIN = 0.05
README = {  # plant: per window (fault error over the whole window, ftc_true_ratio of the window)
    "manipulator": [(0.076, 0.115), (0.215, 0.826)],
    "three-tank": [(0.274, 0.182)],
    "quadruple-tank": [(0.147, 0.060), (0.071, 0.163)],
}


@pytest.mark.slow
@pytest.mark.parametrize("name", list(README))
def test_the_readme_figures(name):
    d = Design.load(GENERATED / name.replace("-", "_") / "design.json")
    sc = SCENARIOS[name]()
    m = simulate(d, load_plant(name), sc, paths=20, seed=1, progress=False, detect=False).metrics
    for w, (err, ratio) in zip(m["windows"], README[name], strict=True):
        assert w["fault_rel_rms_error"] == pytest.approx(err, rel=MARGIN, abs=0.0015), (w["fault"], w)
        assert w["ftc_true_ratio"] == pytest.approx(ratio, rel=MARGIN, abs=0.0015), (w["fault"], w)
        # README: "Every output of the three is below 1" (issue #38: no output worse than none)
        assert max(w["ftc_true_ratio_per_output"]) < 1.0, (w["fault"], w["ftc_true_ratio_per_output"])
