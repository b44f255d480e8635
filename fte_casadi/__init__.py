"""fte_casadi: fault estimation and fault-tolerant control for stochastic T-S fuzzy systems."""

from .design import Design as Design
from .errors import FteError as FteError
from .errors import InfeasibleDesignError as InfeasibleDesignError
from .model import Plant as Plant
from .model import PlantBuilder as PlantBuilder
from .ts import TSModel as TSModel
from .ts import derive as derive

__version__ = "0.1.0"
