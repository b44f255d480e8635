"""Design: augmented system, H and assumption checks, LMIs, certificates, the Design record."""

from ._api import design as design
from ._api import explore as explore
from ._augment import Augmented as Augmented
from ._augment import augment as augment
from ._limits import explain_metrics as explain_metrics
from ._options import DesignOptions as DesignOptions
from ._parts import Dims as Dims
from ._parts import Observer as Observer
from ._parts import Params as Params
from ._record import Design as Design
from ._uio import AssumptionCheck as AssumptionCheck
from ._uio import check_assumptions as check_assumptions
from ._uio import enforce as enforce
from ._uio import invariant_zeros as invariant_zeros
from ._uio import uio_gain as uio_gain

__all__ = ["explain_metrics", "design", "explore", "DesignOptions", "Design", "Dims", "Params", "Observer", "Augmented", "augment", "AssumptionCheck", "check_assumptions", "enforce",
           "invariant_zeros", "uio_gain"]  # fmt: skip
