"""The symbolic stochastic plant (CasADi), its builder and validation."""

from ._plant import Plant as Plant
from ._plant import PlantBuilder as PlantBuilder
from ._validate import triangular_memberships as triangular_memberships
