"""The symbolic stochastic plant (CasADi), its builder and validation."""

from .plant import Plant as Plant
from .plant import PlantBuilder as PlantBuilder
from .validate import triangular_memberships as triangular_memberships
