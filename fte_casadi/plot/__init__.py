"""Figures from simulation results; never computes, never calls show()."""

from .figures import fault_figure as fault_figure
from .figures import figure_set as figure_set
from .figures import output_figure as output_figure
from .figures import output_means_figure as output_means_figure
from .figures import output_paths_figure as output_paths_figure
from .figures import state_figure as state_figure
from .figures import write_figures as write_figures
from .frontier import frontier_figure as frontier_figure
from .frontier import frontier_plot as frontier_plot
from .pareto import pareto_figure as pareto_figure
from .pareto import pareto_plot as pareto_plot
from .sweep import sweep_figure as sweep_figure
from .sweep import sweep_plot as sweep_plot
