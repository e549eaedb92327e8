"""Figures from simulation results (needs the ``plot`` extra: matplotlib)."""

from etobs.plot.figures import plot_error, plot_inter_event_times, plot_states

__all__ = ["plot_error", "plot_inter_event_times", "plot_states"]
