"""Names for the examples in etobs.plot's docstrings (run by ``pytest --doctest-modules src``).

``result`` is a small estimation result to draw (the plot tests' oscillator, its states
named, two runs, 4 s, the arcs and a grid kept; the scipy backend, so nothing is
compiled) and ``tmp_path`` a folder to write figures into. The other tests' settings
are in ``tests/conftest.py``.
"""

from __future__ import annotations

import functools
from typing import Any

import pytest


@functools.cache
def _result() -> Any:
    import numpy as np
    from tests.plot.models import X0, named_sensors

    from etobs import SaveAt, simulate

    save = SaveAt(steps=True, grid=np.linspace(0.0, 4.0, 201))
    return simulate(named_sensors(), X0, 4.0, save=save, backend="scipy")


@pytest.fixture(autouse=True)
def _plot_doctest_names(request: pytest.FixtureRequest) -> None:
    if type(request.node).__name__ != "DoctestItem" or "etobs/plot" not in request.node.path.as_posix():
        return
    names = request.getfixturevalue("doctest_namespace")
    names["result"] = _result()
    names["tmp_path"] = request.getfixturevalue("tmp_path")
