"""``fte tune``: designs chosen for how well they estimate and tolerate, not only for being certified."""

from ._evaluate import evaluate as evaluate

# the face the other subpackages use: internal names, not in __all__ (docs/api.md: what is public)
from ._output import comparison as comparison
from ._output import dominates as dominates
from ._output import fmt_rows as fmt_rows
from ._output import front_documents as front_documents
from ._output import front_table as front_table
from ._output import is_tune_record as is_tune_record
from ._output import write_outputs as write_outputs
from ._search import RULES as RULES
from ._search import Record as Record
from ._search import TuneResult as TuneResult
from ._search import choose as choose
from ._search import pareto_front as pareto_front
from ._search import tune as tune
from ._space import Space as Space
from ._space import space_for as space_for

__all__ = ["evaluate", "RULES", "Record", "TuneResult", "choose", "pareto_front", "tune", "Space", "space_for"]  # fmt: skip
