"""Design: augmented system, H and assumption checks, LMIs, certificates, the Design record."""

from .api import design as design
from .api import explore as explore
from .augment import Augmented as Augmented
from .augment import augment as augment
from .options import DesignOptions as DesignOptions
from .record import Design as Design
from .records import Dims as Dims
from .records import Observer as Observer
from .records import Params as Params
from .uio import AssumptionCheck as AssumptionCheck
from .uio import check_assumptions as check_assumptions
from .uio import enforce as enforce
from .uio import invariant_zeros as invariant_zeros
from .uio import uio_gain as uio_gain

__all__ = ["design", "explore", "DesignOptions", "Design", "Dims", "Params", "Observer", "Augmented", "augment", "AssumptionCheck", "check_assumptions", "enforce",
           "invariant_zeros", "uio_gain"]  # fmt: skip
