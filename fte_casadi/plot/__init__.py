"""Figures from simulation results; never computes, never calls show()."""

from ._detectability import detectability_figure as detectability_figure
from ._detectability import detectability_plot as detectability_plot
from ._figures import fault_figure as fault_figure
from ._figures import figure_set as figure_set
from ._figures import output_figure as output_figure
from ._figures import output_means_figure as output_means_figure
from ._figures import output_paths_figure as output_paths_figure
from ._figures import state_figure as state_figure
from ._figures import write_figures as write_figures
from ._frontier import frontier_figure as frontier_figure
from ._frontier import frontier_plot as frontier_plot
from ._pareto import pareto_figure as pareto_figure
from ._pareto import pareto_plot as pareto_plot
from ._sweep import sweep_figure as sweep_figure
from ._sweep import sweep_plot as sweep_plot
