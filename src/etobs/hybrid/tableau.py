"""The coefficients of the engine's embedded Runge--Kutta pairs and their dense output.

The coefficients are the published ones of Dormand & Prince (1980, the 5(4) pair with
Shampine's 4th-order continuous extension) and of Hairer, Nørsett & Wanner (1993,
DOP853 with its 7th-order continuous extension). We read them from the public class
attributes of :class:`scipy.integrate.RK45` and :class:`scipy.integrate.DOP853` so that
no long decimal table is retyped.

This module holds data only: the engine's kernel template is built with a method's
coefficients as constants (:func:`etobs.hybrid._kernel.tableau_constants`) and computes
the stages, the error norm and the dense output itself, so
``tests/hybrid/test_tableau.py`` checks the order of each pair, of its interpolant and
its error norm on the engine, against closed-form solutions.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.integrate import DOP853, RK45


@dataclass(frozen=True)
class Tableau:
    """An explicit embedded RK pair with first-same-as-last stage and dense output.

    Attributes
    ----------
    name : str
        The method's name in :class:`~etobs.hybrid.SolverOptions` (``method``).
    order, error_order : int
        Order of the solution and of the embedded estimate that controls the step.
    a : ndarray, shape (s, s)
        Stage coefficients (strictly lower triangular).
    b, c : ndarray, shape (s,)
        Weights and nodes of the ``s`` stages.
    e : ndarray, shape (s + 1,)
        Weights of the error estimate ``h sum_k e_k K_k``; ``K_s = f(t + h, y_new)``
        is the first-same-as-last stage.
    e_low : ndarray of shape (s + 1,), or None
        DOP853's 3rd-order estimate, which corrects the 5th-order one ``e``.
    dense_a : ndarray of shape (extra, s + 1 + extra), or None
        DOP853's extra stages of the continuous extension (their ``a`` rows).
    dense_c : ndarray of shape (extra,), or None
        Their nodes.
    dense_d : ndarray
        Dense-output weights: Dormand--Prince's ``P`` of shape (s + 1, 4), DOP853's
        ``D`` of shape (4, s + 1 + extra).

    """

    name: str
    order: int
    error_order: int
    a: np.ndarray
    b: np.ndarray
    c: np.ndarray
    e: np.ndarray
    e_low: np.ndarray | None
    dense_a: np.ndarray | None
    dense_c: np.ndarray | None
    dense_d: np.ndarray

    @property
    def stages(self) -> int:
        """Number of stages of one step (the FSAL stage excluded)."""
        return int(self.b.shape[0])


def _dopri5() -> Tableau:
    s = RK45.n_stages
    a = np.zeros((s, s))
    a[:, : RK45.A.shape[1]] = RK45.A
    return Tableau(
        name="dopri5",
        order=5,
        error_order=4,
        a=a,
        b=np.asarray(RK45.B, float),
        c=np.asarray(RK45.C, float),
        e=np.asarray(RK45.E, float),
        e_low=None,
        dense_a=None,
        dense_c=None,
        dense_d=np.asarray(RK45.P, float),
    )


def _dop853() -> Tableau:
    s = DOP853.n_stages
    return Tableau(
        name="dop853",
        order=8,
        error_order=7,
        a=np.asarray(DOP853.A[:s, :s], float),
        b=np.asarray(DOP853.B, float),
        c=np.asarray(DOP853.C[:s], float),
        e=np.asarray(DOP853.E5, float),
        e_low=np.asarray(DOP853.E3, float),
        dense_a=np.asarray(DOP853.A_EXTRA, float),
        dense_c=np.asarray(DOP853.C_EXTRA, float),
        dense_d=np.asarray(DOP853.D, float),
    )


TABLEAUS: dict[str, Tableau] = {"dopri5": _dopri5(), "dop853": _dop853()}
