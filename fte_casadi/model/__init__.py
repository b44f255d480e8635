"""The symbolic stochastic plant (CasADi), its builder and validation."""

# the face the other subpackages use: internal names, not in __all__ (docs/api.md: what is public)
from ._fingerprint import PARTS as PARTS
from ._fingerprint import changed_parts as changed_parts
from ._fingerprint import plant_fingerprint as plant_fingerprint
from ._plant import Plant as Plant
from ._plant import PlantBuilder as PlantBuilder
from ._tape import read_tape as read_tape
from ._tape import write_tape as write_tape
from ._validate import triangular_memberships as triangular_memberships

__all__ = ["Plant", "PlantBuilder", "triangular_memberships"]  # fmt: skip
