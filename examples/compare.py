"""
Comparing triggering rules
==========================

Run the paper's dynamic rule and the usual baselines on the robot arm, from the same
initial states, on an ideal and a lossy network: the comparison's table and its trade-off.
"""

# %%
# The comparison's spec
# ---------------------
# The same tables as ``etobs compare robot_arm`` (docs/extensions.md), with fewer runs
# and a shorter horizon. Each ``[[rules]]`` entry replaces every node's rule: ``base`` is
# the factory's own (the paper's dynamic rule, ``sigma_i alpha_i(eta_i)`` added to the
# threshold ``eps_i``), ``static`` drops the dynamic variable, and ``sample_period`` runs
# the paper's rule only at the samples ``t_k = k T``, as a sensor node does. Every rule
# also runs on a network that loses 20 % of the packets and delays the others by 10 ms.
import tempfile

from etobs.experiments.compare import compare
from etobs.experiments.compare_spec import parse_compare_spec
from etobs.plot import plot_tradeoff

spec = parse_compare_spec(
    {
        "name": "robot_arm_rules",
        "system": {"factory": "robot_arm"},
        "initial_states": {"low": [0, 0, 0, 0], "high": [20, 10, 20, 10], "runs": 4, "seed": 2023},
        "horizon": {"t_end": 10.0},
        "metrics": {"transmissions_window": [0.0, 10.0], "error_window": [5.0, 10.0]},
        "rules": [
            {"name": "dynamic (paper)", "kind": "base"},
            {"name": "static, sigma = 0", "kind": "static"},
            {"name": "send-on-delta 0.5", "kind": "send_on_delta", "delta": 0.5},
            {"name": "periodic 0.25 s", "kind": "periodic", "period": 0.25},
            {"name": "paper's, sampled at 10 ms", "kind": "base", "sample_period": 0.01},
        ],
        "networks": [{"name": "ideal"}, {"name": "20 % loss, 10 ms", "delay": 0.01, "loss": 0.2}],
    }
)

# %%
# Running it
# ----------
# Like a sweep, a comparison stores its chunks of runs in a folder (a temporary one here)
# and ``executor="serial"`` runs them in this process.
with tempfile.TemporaryDirectory() as out:
    comparison = compare(spec, out, executor="serial", progress=False)
print(comparison.markdown())

# %%
# The trade-off
# -------------
# Mean transmissions against the mean error, one colour per rule and one marker per
# network; each bar reaches the worst run. Lower left is better. The nodes do not see the
# network, so it changes no transmission count, only the error; sampling the paper's
# rule at 10 ms changes little.
fig, ax = plot_tradeoff(comparison)
