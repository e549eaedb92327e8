"""Names for the examples in etobs.plot's docstrings (run by ``pytest --doctest-modules src``).

``result`` is a small estimation result to draw (the README's oscillator, two runs, 4 s,
the arcs and a grid kept; the scipy backend, so nothing is compiled) and ``tmp_path`` a
folder to write figures into. The other tests' settings are in ``tests/conftest.py``.
"""

from __future__ import annotations

import functools
from typing import Any

import pytest


@functools.cache
def _result() -> Any:
    import numpy as np

    from etobs import (
        DynamicRule,
        EstimationProblem,
        Linear,
        Node,
        Plant,
        Quadratic,
        SaveAt,
        Sinusoid,
        luenberger,
        simulate,
    )

    A = np.array([[0.0, 1.0], [-2.0, -0.5]])
    plant = Plant(
        lambda t, x, u, v: A @ x + v, lambda x: x, n_x=2, n_y=2, n_v=2,
        state_names=["position", "velocity"], state_units=["m", "m/s"],
    )  # fmt: skip
    rule = DynamicRule(gamma=Quadratic(5.0), alpha=Linear(2.0), sigma=10.0, c=0.01, eps=0.01, eta0=1.0)
    problem = EstimationProblem(
        plant,
        luenberger(lambda t, x, u: A @ x, L=np.eye(2) * 3.0),
        nodes=[Node((0,), rule, name="sensor 1"), Node((1,), rule, name="sensor 2")],
        v=Sinusoid(amplitude=[0.0, 0.1], omega=1.0),
    )
    grid = np.linspace(0.0, 4.0, 201)
    return simulate(
        problem, [[1.0, 0.0], [0.0, 2.0]], 4.0, save=SaveAt(steps=True, grid=grid), backend="scipy"
    )


@pytest.fixture(autouse=True)
def _plot_doctest_names(request: pytest.FixtureRequest) -> None:
    if type(request.node).__name__ != "DoctestItem" or "etobs/plot" not in request.node.path.as_posix():
        return
    names = request.getfixturevalue("doctest_namespace")
    names["result"] = _result()
    names["tmp_path"] = request.getfixturevalue("tmp_path")
