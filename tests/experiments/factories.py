"""Sweep factories for the tests: a cheap scalar system that can misbehave on demand."""

import os
import sys
import time
from pathlib import Path

import numpy as np

import etobs
from etobs import DynamicRule, EstimationProblem, Linear, Node, Observer, Plant, Quadratic


def _plant(t, x, u, v, p):
    return -p[0] * x + np.sin(t)


def _output(x, p):
    return x


def _observer(t, z, u, ybar, yhat, p):
    return -p[0] * z + np.sin(t) + 2.0 * (ybar - yhat)


def _in_a_chunk():
    """Whether the factory is called to run a chunk, not by the spec's up-front check.

    A sweep builds every row's problem before any run (:meth:`SweepSpec.check`); the
    misbehaviours below stand for a chunk that fails or dies while it runs, so they act
    only inside :func:`etobs.experiments.runner.run_task`.
    """
    frame = sys._getframe(1)
    while frame is not None:
        if frame.f_code.co_name == "run_task":
            return True
        frame = frame.f_back
    return False


@etobs.factory
def scalar(
    k=1.0,
    eps=0.01,
    fail=False,
    delay=0.0,
    die_marker="",
    die_always=False,
    started="",
    refuse=False,
    sigma=0.5,
):
    """x' = -k x + sin t measured by one node; observer xhat' = -k xhat + sin t + 2 (ybar - xhat).

    In a chunk only: fail: raise (a chunk that fails); delay: sleep (a slow chunk);
    die_marker: kill the calling process the first time (a worker that dies), creating
    the marker file; started: create this file when called (a test knows the sweep is
    under way). Always: refuse: raise (a row the factory refuses); sigma: the rule's.
    """
    if refuse:
        raise ValueError("this row fails on purpose")
    if _in_a_chunk():
        _misbehave(fail, delay, die_marker, die_always, started)
    # k travels as the parameters: every row runs the same compiled functions
    plant = Plant(f_p=_plant, h=_output, n_x=1, n_y=1, params=[k])
    obs = Observer(f_o=_observer, n_z=1, params=[k])
    rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=sigma, c=0.1, b=1.0, eps=eps, eta0=1.0)
    return EstimationProblem(plant, obs, [Node((0,), rule)])


def _misbehave(fail, delay, die_marker, die_always, started):
    if fail:
        raise ValueError("this row fails on purpose")
    if started:
        Path(started).write_text("called")
    if delay:
        time.sleep(delay)
    if die_always:
        os._exit(3)
    if die_marker and not Path(die_marker).exists():
        Path(die_marker).write_text("died once")
        os._exit(3)


@etobs.factory
def scalar_network(k=1.0, loss=0.0, delay=0.0, relative=False):
    """The scalar system behind a lossy, delayed network, optionally with the relative rule."""
    from etobs import Link, Network, RelativeRule

    pb = scalar(k=k)
    rule = RelativeRule(rho=0.1, eps=0.01) if relative else pb.nodes[0].rule
    return EstimationProblem(
        pb.plant, pb.observer, [Node((0,), rule)], network=Network(Link(delay=delay, loss=loss), seed=5)
    )


@etobs.factory
def not_a_problem(**kwargs):
    """A marked factory that returns something else (a dict)."""
    return {}


def unmarked(k=1.0):
    """The scalar system, but not marked as a factory: a spec may not call it."""
    return scalar(k=k)
