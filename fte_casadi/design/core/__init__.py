"""The numerical core of the design: the LMIs and their registry (:mod:`.lmis`), the conic problems and their
barrier centring (:mod:`.sdp`, :mod:`.barrier`), the two formulations of steps 3 and 5 (:mod:`.conditioned`,
:mod:`.paper`) with the decay-rate search (:mod:`.decay`) and the fault-error bound (:mod:`.bounds`,
:mod:`.bound_objective`), the feasibility bounds (:mod:`.diagnose`) and the a-posteriori certificate
(:mod:`.certify`). Nothing here retries, searches parameters or builds a Design record."""

from .lmis import LMI as LMI
from .lmis import LMIS as LMIS
from .lmis import register as register
from .lmis import unregister as unregister

__all__ = ["LMI", "LMIS", "register", "unregister"]
