"""
A sweep
=======

Sweep the threshold ``eps_i`` of the robot arm's rules, for the paper's dynamic rule and
the static rule, over a few random initial states: a tidy table and the trade-off it shows.
"""

# %%
# The spec
# --------
# A sweep is a spec (the keys of ``etobs sweep``, docs/sweeps.md) given here as a
# dictionary: the factory, a grid of its arguments (``eps_i``, the same for both nodes),
# scenarios applied to every row (``sigma_i = 0`` makes the paper's rule static), the
# box of initial states and the horizon. Every row and scenario runs from the same
# initial states (common random numbers).
import tempfile

from matplotlib.figure import Figure

from etobs.experiments import parse_spec, run_sweep

spec = parse_spec(
    {
        "name": "robot_arm_eps",
        "system": {"factory": "robot_arm"},
        "grid": {"eps": [0.1, 1.0, 10.0, 100.0]},
        "scenarios": [{"name": "dynamic", "sigma": [600.0, 800.0]}, {"name": "static", "sigma": [0.0, 0.0]}],
        "initial_states": {"low": [0, 0, 0, 0], "high": [20, 10, 20, 10], "runs": 5, "seed": 2023},
        "horizon": {"t_end": 10.0},
        "metrics": {"transmissions_window": [0.0, 10.0], "error_window": [5.0, 10.0]},
    }
)

# %%
# Running it
# ----------
# ``run_sweep`` stores every chunk of runs in its output folder (so that a sweep can be
# resumed); a temporary folder will do here. ``executor="serial"`` runs in this process.
with tempfile.TemporaryDirectory() as out:
    sweep = run_sweep(spec, out, executor="serial", progress=False)

# %%
# The table
# ---------
# One row per (row, scenario): transmissions of both nodes on ``[0, 10]`` s, the error
# ``max |x - xhat|`` on ``[5, 10]`` s (mean over the runs), and the shortest time between
# two transmissions of sensor 2 over all runs (the quantity Theorem 4 bounds from below).
table = sweep.to_pandas("aggregate")
columns = [
    "scenario",
    "eps",
    "completed",
    "transmissions_mean",
    "error_mean",
    "min_inter_event_time_node1_min",
]
print(table[columns].to_string(index=False, float_format="{:.4g}".format))

# %%
# Transmissions and error against ``eps``
# ---------------------------------------
# A larger ``eps_i`` sends less and estimates worse; at every ``eps_i`` the dynamic rule
# sends several times less than the static one, for a somewhat larger error.
# The bars span one standard deviation over the runs.
fig = Figure(figsize=(8.0, 3.4), layout="constrained")
ax_sent, ax_error = fig.subplots(1, 2, sharex=True)
for name, group in table.groupby("scenario", sort=False):
    ax_sent.errorbar(
        group["eps"], group["transmissions_mean"], group["transmissions_std"], marker="o", label=name
    )
    ax_error.errorbar(group["eps"], group["error_mean"], group["error_std"], marker="o", label=name)
ax_sent.set(xscale="log", yscale="log", xlabel=r"$\varepsilon_i$", ylabel="transmissions on [0, 10] s")
ax_error.set(xscale="log", yscale="log", xlabel=r"$\varepsilon_i$", ylabel=r"max $|x - \hat x|$ on [5, 10] s")
for ax in (ax_sent, ax_error):
    ax.grid(alpha=0.3, which="both")
    ax.legend(title="rule", fontsize="small")
