"""Design: augmented system, H and assumption checks, LMIs, certificates, the Design record."""

from ._api import default_observer_rate as default_observer_rate  # internal: fte tune
from ._api import design as design
from ._api import design_at_rate_fraction as design_at_rate_fraction  # internal: fte tune
from ._api import explore as explore
from ._augment import Augmented as Augmented
from ._augment import augment as augment

# the face the other subpackages use: internal names, not in __all__ (docs/api.md: what is public)
from ._docchecks import param_problem as param_problem
from ._identities import identity_failures as identity_failures
from ._isolation import crosstalk as crosstalk
from ._isolation import crosstalk_held as crosstalk_held
from ._isolation import overshoot as overshoot
from ._limits import explain_metrics as explain_metrics
from ._limits import fed_faults as fed_faults
from ._matfile import is_fte_mat as is_fte_mat
from ._model_form import missed_motion as missed_motion  # internal: fte derive
from ._options import DesignOptions as DesignOptions
from ._parts import Dims as Dims
from ._parts import Observer as Observer
from ._parts import Params as Params
from ._pipeline import u_reference as u_reference
from ._recertify import recertify as recertify
from ._record import REQUIRED_KEYS as REQUIRED_KEYS
from ._record import Design as Design
from ._remedy import remedies as remedies
from ._summary import design_summary as design_summary
from ._uio import AssumptionCheck as AssumptionCheck
from ._uio import check_assumptions as check_assumptions
from ._uio import enforce as enforce
from ._uio import invariant_zeros as invariant_zeros
from ._uio import uio_gain as uio_gain
from .core._certify import failures as failures
from .core._conditioned import KAPPA as KAPPA
from .core._diagnose import sigma_max as sigma_max

__all__ = ["explain_metrics", "design", "explore", "DesignOptions", "Design", "Dims", "Params", "Observer", "Augmented", "augment", "AssumptionCheck", "check_assumptions", "enforce",
           "invariant_zeros", "uio_gain"]  # fmt: skip
