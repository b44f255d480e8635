"""The diagnosis of a refused design, in one place: the parameter search (:mod:`._parameters`), the bounds and
checked advice of an infeasible (45) or (46) (:mod:`._explain`), and the cause behind it (:mod:`._naming`): the
plant's diffusion (:mod:`._diffusion`), a fault the outputs tell apart only weakly (:mod:`._separability`), the
cover's vertices (:mod:`._other_cover`). Each refusal is a :class:`~fte_casadi.errors.Refusal` record that code
reads by field; the numerical bounds it names are :mod:`fte_casadi.design.core._diagnose`'s."""

from ._diffusion import Tolerance as Tolerance
from ._diffusion import scaled as scaled
from ._diffusion import scaled_model as scaled_model
from ._diffusion import tolerance as tolerance
from ._explain import beyond_sigma_max as beyond_sigma_max
from ._explain import explain_45 as explain_45
from ._explain import explain_46 as explain_46
from ._naming import DECIDING_SOLVER as DECIDING_SOLVER
from ._naming import Diffusion as Diffusion
from ._naming import blocking_diffusion as blocking_diffusion
from ._naming import name_cause as name_cause
from ._naming import weak_faults as weak_faults
from ._necessary import Limit as Limit
from ._necessary import decide as decide
from ._necessary import describe as describe
from ._necessary import limits as limits
from ._other_cover import OtherCover as OtherCover
from ._parameters import Trial as Trial
from ._parameters import choose as choose
from ._parameters import try_design as try_design
from ._separability import Blocking as Blocking
from ._separability import Faults as Faults
from ._separability import blocking as blocking

__all__ = ["Tolerance", "scaled_model", "tolerance", "beyond_sigma_max", "explain_45", "explain_46", "DECIDING_SOLVER",
           "Diffusion", "blocking_diffusion", "name_cause", "weak_faults", "OtherCover", "Trial", "choose", "scaled", "Limit", "decide", "describe", "limits",
           "try_design", "Blocking", "Faults", "blocking"]  # fmt: skip
