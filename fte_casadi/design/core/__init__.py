"""The numerical core of the design: the LMIs and their registry (:mod:`._lmis`), the conic problems and their
barrier centring (:mod:`._sdp`, :mod:`._barrier`), the two formulations of steps 3 and 5 (:mod:`._conditioned` with
:mod:`._step5`, :mod:`._paper`) with the decay-rate search (:mod:`._decay`) and the fault-error bound (:mod:`._bounds`,
:mod:`._bound_objective`), the feasibility bounds (:mod:`._diagnose`) and the a-posteriori certificate
(:mod:`._certify`). Nothing here retries, searches parameters or builds a Design record."""

from ._conditioned import step3 as step3
from ._lmis import LMI as LMI
from ._lmis import LMIS as LMIS
from ._lmis import lmi45 as lmi45
from ._lmis import lmi46_terms as lmi46_terms
from ._lmis import register as register
from ._lmis import unregister as unregister

__all__ = ["LMI", "LMIS", "register", "unregister"]
