"""
The robot arm: the paper's case study
=====================================

The flexible-joint arm of section 8, two sensor nodes with the dynamic rule, from the
paper's initial state: the states and their estimates, the error, the inter-event times,
and a two-panel figure for a paper (states and held outputs, named and with units) written
as PDF.
"""

import numpy as np

from etobs import SaveAt, simulate
from etobs.examples import X0_PAPER, robot_arm
from etobs.plot import (
    paper_figure,
    paper_style,
    plot_error,
    plot_held_outputs,
    plot_inter_event_times,
    plot_states,
    save_figure,
)

# %%
# Simulate 30 s, keeping the arcs (exact jumps) and a grid of 3001 points for smooth curves.
problem = robot_arm()  # every number is the paper's
result = simulate(problem, X0_PAPER, 30.0, save=SaveAt(steps=True, grid=np.linspace(0.0, 30.0, 3001)))
print(result)
print(result.to_pandas("summary")[["status", "transmissions_node0", "transmissions_node1", "max_error"]])

# %%
# The paper's Fig. 3: the states, named by the model with their units, and their estimates.
fig_states, _ = plot_states(result)

# %%
# Fig. 4: the norm of the estimation error.
fig_error, _ = plot_error(result)

# %%
# Fig. 5 on a logarithmic axis: millisecond intervals stay visible next to gaps of seconds.
fig_gaps, _ = plot_inter_event_times(result, logy=True)

# %%
# A figure for a paper, two columns wide: two plot calls on one figure, the first 10 s.
# Each call gets one Axes, so the states (the motor's and the link's angle, in rad) and the
# nodes' values are overlaid in it, each named with its unit; ``save_figure`` writes a
# vector PDF, its text kept as text.
with paper_style():
    fig, (top, bottom) = paper_figure(columns=2, nrows=2, height=3.6)
    plot_states(result, components=[0, 2], ax=top, window=(0.0, 10.0))
    plot_held_outputs(result, ax=bottom, window=(0.0, 10.0))
    top.set_title("(a) angles (solid) and their estimates (dashed)", loc="left")
    bottom.set_title("(b) held outputs (steps) over the measured outputs", loc="left")
    save_figure(fig, "robot-arm.pdf")
