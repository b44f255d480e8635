"""``fte tune``: designs chosen for how well they estimate and tolerate, not only for being certified."""

from ._evaluate import evaluate as evaluate
from ._search import RULES as RULES
from ._search import Record as Record
from ._search import TuneResult as TuneResult
from ._search import choose as choose
from ._search import pareto_front as pareto_front
from ._search import tune as tune
from ._space import Space as Space
from ._space import space_for as space_for
