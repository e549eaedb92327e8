"""
Design end to end
=================

Design the robot arm's observer gain and triggering rules for a requested guarantee with
``etobs.design``, read the certificate, and simulate the certified design against it.
"""

# %%
# The observer gain (section 8)
# -----------------------------
# The arm is ``x' = A x + B u + G phi(H x) + v`` with ``phi(s) = 3.3 sin(s)``, whose slope
# lies in ``[-3.3, 3.3]``. The error dynamics ``A + G s H - L C`` then lie in a polytope
# with two vertices, and ``observer_gain`` solves the LMIs at both for ``L`` and ``P``:
# here the fastest guaranteed decay with ``||L|| <= 30``.
import numpy as np
from matplotlib.figure import Figure

from etobs import SaveAt, min_inter_event_time, simulate, transmission_counts
from etobs.design import (
    certify,
    estimate_output_rate,
    observer_gain,
    propose_rules,
    quadratic_iss_gains,
    slope_vertices,
)
from etobs.examples import X0_PAPER, robot_arm
from etobs.examples.robot_arm import SECTOR, A, C, G  # the paper's matrices; y_1 = x_1, y_2 = x_2
from etobs.plot import plot_error, plot_inter_event_times

vertices = slope_vertices(G[:, None], [[0.0, 0.0, 1.0, 0.0]], [(-SECTOR, SECTOR)])  # H x = x_3
gain = observer_gain(A, C, vertices, objective="max_decay", max_gain=30.0)
print("L =\n", gain.L.round(2))

# %%
# ISS gains and rules for a requested guarantee
# ---------------------------------------------
# ``V = xi' P xi`` gives Assumption 2 with ``alpha(s) = a s`` and ``gamma_i(s) = k_i s^2``
# (``c_v``, ``c_i`` split ``Q`` among the cross terms). ``propose_rules`` then picks
# ``eps_i`` and ``alpha_i`` so that Theorem 2 holds with the rate ``a_U`` and bound ``mu``
# asked. Noise is left out: with it, section 7.2 would also ask ``eps_i > gamma_i(2 m_i)``.
iss = quadratic_iss_gains(gain, [[0], [1]], c_v=0.1, c=[0.1, 0.1])
a_U = 0.5 * iss.a
rules = propose_rules(iss, sigma=[1.0, 1.0], c=[0.1, 0.1], a_U=a_U, mu=100.0).rules
params = {k: [getattr(r, k) for r in rules] for k in ("sigma", "c", "eps")}
params |= {"a": [r.alpha.a for r in rules], "ell": [r.gamma.ell for r in rules], "eta0": 0.0}
problem = robot_arm(L=gain.L, noise=False, **params)

# %%
# The certificate
# ---------------
# Theorem 4's ``tau_i = gamma_i^{-1}(eps_i) / E_i`` needs a bound ``E_i`` on ``|dy_i/dt|``:
# here the largest rate seen on the two runs simulated below, plus 20 %, which the
# certificate lists among what it assumes.
x0 = [X0_PAPER, [10.0, 5.0, 10.0, 5.0]]  # two runs
E = 1.2 * estimate_output_rate(problem, x0, 20.0)
cert = certify(problem, iss, a_U=a_U, E=E)
print(repr(cert))
tau = np.array([nd.tau for nd in cert.nodes])  # Theorem 4, per node

# %%
# Simulating the certified design
# -------------------------------
# The error settles well inside the certified ultimate bound on ``|x - xhat|`` (the
# guarantee is conservative), and no node sends faster than its ``tau_i``.
result = simulate(problem, x0, 20.0, save=SaveAt(steps=False, grid=np.linspace(0.0, 20.0, 2001)))
print("transmissions per run and node:", transmission_counts(result).tolist())
print("min inter-event times [s]:", min_inter_event_time(result).round(5).tolist(), "tau_i:", tau.round(5))

fig = Figure(figsize=(7.0, 5.5), layout="constrained")
ax_error, ax_gaps = fig.subplots(2, 1, sharex=True)
plot_error(result, run=[0, 1], ax=ax_error)
ax_error.axhline(cert.error_bound, color="k", ls="--", label="certified bound (Theorem 2)")
ax_error.legend(fontsize="small")
plot_inter_event_times(result, run=0, logy=True, ax=ax_gaps)
for i, tau_i in enumerate(tau):
    ax_gaps.axhline(tau_i, color=f"C{i}", ls="--", lw=0.8, label=rf"$\tau_{i + 1}$ (Theorem 4)")
ax_gaps.legend(fontsize="small", ncol=2)
