"""Shared results for the plot tests: small simulations, solved once for the folder."""

import numpy as np
import pytest

matplotlib = pytest.importorskip("matplotlib", reason="the plot extra is not installed")
matplotlib.use("Agg")  # headless; the figures are matplotlib.figure.Figure, never pyplot's

from etobs import SaveAt, simulate  # noqa: E402
from tests.plot.models import T_END, X0, two_sensors  # noqa: E402


@pytest.fixture(scope="package")
def arcs_only():
    """Two runs, arcs kept (SaveAt's default), no grid."""
    return simulate(two_sensors(), x0=X0, t_end=T_END, backend="scipy")


@pytest.fixture(scope="package")
def arcs_and_grid():
    return simulate(
        two_sensors(), x0=X0, t_end=T_END, save=SaveAt(grid=np.linspace(0, T_END, 251)), backend="scipy"
    )


@pytest.fixture(scope="package")
def grid_only():
    return simulate(
        two_sensors(),
        x0=X0,
        t_end=T_END,
        save=SaveAt(steps=False, grid=np.linspace(0, T_END, 101)),
        backend="scipy",
    )
