"""``fte tune``: designs chosen for how well they estimate and tolerate, not only for being certified."""

from .evaluate import evaluate as evaluate
from .search import RULES as RULES
from .search import Record as Record
from .search import TuneResult as TuneResult
from .search import choose as choose
from .search import pareto_front as pareto_front
from .search import tune as tune
from .space import Space as Space
from .space import space_for as space_for
