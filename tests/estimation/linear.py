"""A lightly damped linear oscillator with a known input, for the extensions' tests.

``x' = A x + B u``, ``y = C x`` with ``u = sin(t)``, and a Luenberger observer with gain
``L`` (``A - L C`` has eigenvalues -2 and -3). The estimation error obeys
``xhat - x = e_x``, ``e_x' = (A - L C) e_x + L e + B e_u`` where ``e = ybar - y`` and
``e_u = ubar - u`` are the network-induced errors, so
``|e_x(t)| <= |e_x(0)| |exp((A - LC) t)| + sup|e| ||G_y||_1 + sup|e_u| ||G_u||_1``
with ``G_y(s) = exp((A - LC) s) L`` and ``G_u(s) = exp((A - LC) s) B``.
"""

import numpy as np
from scipy.integrate import quad
from scipy.linalg import expm

import etobs
from etobs import EstimationProblem, Node, Observer, Plant
from etobs.model import Sinusoid

A = np.array([[0.0, 1.0], [-1.0, -0.2]])
B = np.array([[0.0], [1.0]])
C = np.array([[1.0, 0.0]])
L = np.array([[4.8], [4.04]])  # det(sI - A + LC) = s^2 + 5 s + 6
A_CL = A - L @ C


def plant() -> Plant:
    return Plant(f_p=lambda t, x, u, v: A @ x + B @ u, h=lambda x: C @ x, n_x=2, n_y=1, n_u=1)


def observer() -> Observer:
    def f_o(t, z, u, ybar, yhat):
        return A @ z + B @ u + L @ (ybar - yhat)

    return Observer(f_o=f_o, n_z=2)


def problem(rule, **kw) -> EstimationProblem:
    kw.setdefault("u", Sinusoid(amplitude=[1.0], omega=1.0))
    return EstimationProblem(plant=plant(), observer=observer(), nodes=[Node((0,), rule, name="y")], **kw)


def l1_gain(G: np.ndarray) -> float:
    """``int_0^inf |exp(A_CL s) G| ds`` (spectral norm), numerically."""
    return quad(lambda s: np.linalg.norm(expm(A_CL * s) @ G, 2), 0.0, 40.0, limit=200)[0]


@etobs.factory
def factory(sigma: float = 2.0, eps: float = 0.01, noise: bool = False) -> EstimationProblem:
    """The oscillator with a dynamic rule, as a spec's ``system.factory``."""
    from etobs import DynamicRule, Linear, Quadratic

    rule = DynamicRule(gamma=Quadratic(4.0), alpha=Linear(1.0), sigma=sigma, c=0.2, b=1.0, eps=eps, eta0=0.1)
    m = Sinusoid(amplitude=[0.001], omega=20.0) if noise else None
    return problem(rule, m=m)
