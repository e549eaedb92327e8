"""A researcher's first hour
=========================
A Van der Pol oscillator, from model to table to plot: written once, for one run."""

import numpy as np

from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, SaveAt, luenberger, simulate
from etobs.plot import plot_held_outputs


def vdp(t, x, u, v, p):
    """Van der Pol, x'' = mu (1 - x^2) x' - x + v."""
    return np.array([x[1], p[0] * (1.0 - x[0] ** 2) * x[1] - x[0] + v[0]])


plant = Plant(vdp, lambda x, p: x.copy(), n_x=2, n_y=2, n_v=1, params=[1.0])  # y = (position, speed)
observer = luenberger(lambda t, x, u: np.array([x[1], (1.0 - x[0] ** 2) * x[1] - x[0]]), L=np.eye(2) * 4.0)
rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=2.0, c=0.2, eps=0.05)
problem = EstimationProblem(plant, observer, nodes=[Node([0], rule), Node([1], rule)], v=[0.0])

x0 = np.random.default_rng(1).uniform(-2.0, 2.0, size=(8, 2))  # eight runs at once
result = simulate(problem, x0, 20.0, save=SaveAt(steps=True, grid=np.linspace(0.0, 20.0, 401)))
print(result)  # a few lines: status, transmissions per node, backend
summary = result.to_pandas("summary")  # one row per run
print(summary[["status", "transmissions_node0", "transmissions_node1", "max_error"]])
sent = result.to_pandas("transmissions")  # one row per transmission, with the value sent
print(sent.groupby(["run", "node"])["t"].diff().groupby(sent["node"]).min())  # shortest gap per node
fig, axes = plot_held_outputs(result, run=0)  # ybar_i as steps over y_i, transmissions marked
fig.savefig("first_hour.png", dpi=100)
