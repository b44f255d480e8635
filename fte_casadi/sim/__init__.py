"""Scenarios (faults, disturbances, noise) and the compiled Euler-Maruyama Monte Carlo engine."""

from .engine import simulate as simulate
from .metrics import metrics as metrics
from .metrics import metrics_from_arrays as metrics_from_arrays
from .result import RunData as RunData
from .result import SimulationResult as SimulationResult
from .result import load_result as load_result
from .result import save_result as save_result
from .scenario import Bias as Bias
from .scenario import Drift as Drift
from .scenario import LossOfEffectiveness as LossOfEffectiveness
from .scenario import Scenario as Scenario
from .scenario import Sinusoid as Sinusoid
from .scenario import Stuck as Stuck
from .scenario import UniformNoise as UniformNoise
