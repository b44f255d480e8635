"""fte_casadi: fault estimation and fault-tolerant control for stochastic T-S fuzzy systems.

The path of the data: a symbolic :class:`Plant` (built with :class:`PlantBuilder`) becomes a
T-S model (:func:`derive`), the T-S model a certified :class:`Design` (:func:`design`), the design
drives a Monte Carlo simulation (:func:`simulate`, :func:`metrics`) and becomes embedded C
(:func:`generate_c`) through one CasADi Function (:func:`step_function`).
"""

# first: a Ctrl-C while the modules below load ends `fte` with status 130 and one line, not a traceback
from . import _interrupt as _interrupt  # noqa: F401
from ._version import __version__ as __version__  # pyproject.toml's, read from the metadata
from .codegen import generate_c as generate_c
from .design import Design as Design
from .design import design as design
from .errors import FteError as FteError
from .errors import InfeasibleDesignError as InfeasibleDesignError
from .model import Plant as Plant
from .model import PlantBuilder as PlantBuilder
from .sim import Scenario as Scenario
from .sim import metrics as metrics
from .sim import simulate as simulate
from .step import step_function as step_function
from .ts import TSModel as TSModel
from .ts import derive as derive

_interrupt.loaded()  # Python's Ctrl-C handler again; an interrupt swallowed while the modules loaded ends here
