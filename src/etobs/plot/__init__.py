"""Figures from simulation results (needs the ``plot`` extra: matplotlib)."""

from etobs.plot.arc import plot_hybrid_arc
from etobs.plot.compare import plot_tradeoff
from etobs.plot.figures import plot_error, plot_inter_event_times, plot_states
from etobs.plot.held import plot_held_outputs
from etobs.plot.layout import COLUMN_WIDTH, PAPER_RC, Drawn, paper_figure, paper_style, save_figure
from etobs.plot.trace import plot_trace
from etobs.plot.tuning import plot_front

__all__ = [
    "COLUMN_WIDTH",
    "PAPER_RC",
    "Drawn",
    "paper_figure",
    "paper_style",
    "plot_error",
    "plot_front",
    "plot_held_outputs",
    "plot_hybrid_arc",
    "plot_inter_event_times",
    "plot_states",
    "plot_trace",
    "plot_tradeoff",
    "save_figure",
]
