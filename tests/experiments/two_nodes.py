"""A sweep factory with two output nodes that transmit at clearly different rates."""

import numpy as np

import etobs
from etobs import DynamicRule, EstimationProblem, Linear, Node, Observer, Plant, Quadratic


def _plant(t, x, u, v, p):
    return np.array([-x[0] + np.sin(t), -2.0 * x[1] + 5.0 * np.cos(3.0 * t)])


def _output(x, p):
    return x


def _observer(t, z, u, ybar, yhat, p):
    return np.array([-z[0] + np.sin(t), -2.0 * z[1] + 5.0 * np.cos(3.0 * t)]) + 2.0 * (ybar - yhat)


@etobs.factory
def pair(eps0=0.05, eps1=0.0005):
    """Two decoupled scalar plants, each measured by its own node; node 1's finer eps1 sends more."""
    plant = Plant(f_p=_plant, h=_output, n_x=2, n_y=2, params=[0.0])
    obs = Observer(f_o=_observer, n_z=2, params=[0.0])

    def rule(eps):
        return DynamicRule(
            gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.1, b=1.0, eps=eps, eta0=1.0
        )

    return EstimationProblem(plant, obs, [Node((0,), rule(eps0)), Node((1,), rule(eps1))])
