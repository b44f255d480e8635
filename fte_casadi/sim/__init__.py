"""Scenarios (faults, disturbances, noise) and the compiled Euler-Maruyama Monte Carlo engine.

Two names for time steps, one meaning each:

- ``sample_time`` (Ts) is the observer/controller's sample time, everywhere in the package: what a
  design is made and certified for (``Design.observer.sample_time``, ``design(..., sample_time=)``),
  and the step of :func:`~fte_casadi.step.step_function` and of the generated C (``fte codegen --sample-time``).
- ``dt`` is the simulation's step, and is used only here in ``sim/`` and for the scenario
  (``Scenario.dt``, ``simulate(..., dt=)``, ``fte simulate --dt``, the metrics key ``"dt"``): the
  Euler-Maruyama step of the plant. The simulated controller takes one sample per step, so within a
  run the integration step and the controller's sample time are the same number by construction
  (the step Function is built at ``dt``); ``dt`` differs from the design's ``sample_time`` only when
  ``--dt`` asks for it or the design's sample time exceeds its ``ts_max``, and the metrics say so
  (``"dt_change"``).

``ts`` names a T-S model (:class:`~fte_casadi.ts.TSModel`) only; ``ts_max`` (the design document's
``checks.ts_max``) is the largest sample time its discrete observer is stable for.
"""

from ._accommodate import accommodated as accommodated
from ._accommodate import protected as protected
from ._c_check import check_c as check_c
from ._c_check import require_compiler as require_compiler
from ._c_check import require_same_sliding as require_same_sliding
from ._carry import carry_free as carry_free
from ._detectability import attach as attach
from ._detectability import detectability as detectability
from ._engine import calibrate_detection as calibrate_detection
from ._engine import simulate as simulate
from ._fault_shapes import FaultRows as FaultRows
from ._fault_shapes import FaultShape as FaultShape
from ._fault_shapes import FaultSite as FaultSite
from ._metrics import metrics as metrics
from ._metrics import metrics_from_arrays as metrics_from_arrays
from ._noise import GaussianNoise as GaussianNoise
from ._noise import MeasurementNoise as MeasurementNoise
from ._noise import UnknownInput as UnknownInput
from ._noise import UnknownInputTerms as UnknownInputTerms
from ._options import SimulateOptions as SimulateOptions
from ._result import RunData as RunData
from ._result import SimulationResult as SimulationResult
from ._result import load_result as load_result
from ._result import save_result as save_result
from ._scenario import Bias as Bias
from ._scenario import Drift as Drift
from ._scenario import LossOfEffectiveness as LossOfEffectiveness
from ._scenario import Scenario as Scenario
from ._scenario import Sinusoid as Sinusoid
from ._scenario import Stuck as Stuck
from ._scenario import UniformNoise as UniformNoise
