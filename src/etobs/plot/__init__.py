"""Figures from simulation results (needs the ``plot`` extra: matplotlib)."""

from etobs.plot.compare import plot_tradeoff
from etobs.plot.figures import plot_error, plot_inter_event_times, plot_states
from etobs.plot.trace import plot_trace

__all__ = ["plot_error", "plot_inter_event_times", "plot_states", "plot_trace", "plot_tradeoff"]
