"""A scalar plant with a constant slope, whose event times are known in closed form.

Plant ``x' = k``, ``y = x``, no noise; observer ``z' = 0`` (it plays no role in the
rule). After a transmission at ``t_j`` the gap is ``e = -k (t - t_j)`` and, with
``gamma(s) = ell s^2`` and ``alpha(s) = a s``, eq. (14) integrates to

    eta(t_j + tau) = eta_j e^{-a tau}
                     + c ell k^2 (tau^2/a - 2 tau/a^2 + 2/a^3 - 2 e^{-a tau}/a^3).

The next transmission is the root of ``ell k^2 tau^2 = sigma a eta(tau) + eps``
(eq. (15)); then ``eta_{j+1} = b eta(tau)``.
"""

import numpy as np
from scipy.optimize import brentq

from etobs import DynamicRule, EstimationProblem, Linear, Node, Observer, Plant, Quadratic

K, ELL, A, SIGMA, C, B, EPS, ETA0 = 2.0, 5.0, 2.0, 3.0, 0.05, 0.5, 1.0, 10.0


def problem(**kw):
    p = dict(gamma=Quadratic(ELL), alpha=Linear(A), sigma=SIGMA, c=C, b=B, eps=EPS, eta0=ETA0) | kw
    plant = Plant(f_p=lambda t, x, u, v: np.full_like(x, K), h=lambda x: x, n_x=1, n_y=1)
    observer = Observer(f_o=lambda t, z, u, ybar, yhat: np.zeros_like(z), n_z=1)
    return EstimationProblem(plant=plant, observer=observer, nodes=[Node((0,), DynamicRule(**p))])


def eta(tau, eta_j, a=A, c=C, ell=ELL):
    forced = tau**2 / a - 2 * tau / a**2 + 2 / a**3 - 2 * np.exp(-a * tau) / a**3
    return eta_j * np.exp(-a * tau) + c * ell * K**2 * forced


def event_times(n, *, sigma=SIGMA, b=B, c=C):
    times, t, eta_j = [], 0.0, ETA0
    for _ in range(n):

        def g(tau, eta_j=eta_j):
            return ELL * K**2 * tau**2 - sigma * A * eta(tau, eta_j, c=c) - EPS

        tau = brentq(g, 1e-12, 100.0, xtol=1e-15, rtol=1e-15)
        t += tau
        times.append(t)
        eta_j = b * eta(tau, eta_j, c=c)
    return np.array(times)
