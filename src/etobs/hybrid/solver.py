"""The front door of the hybrid solvers, and the contract both of them keep.

Two solvers integrate hybrid systems: the compiled engine (:mod:`etobs.hybrid.compiled`,
the default) and the ``solve_ivp`` reference (:mod:`etobs.hybrid.reference`) that
cross-checks it on the same Python functions. (A third, a batched numpy solver, was
retired once the engine ran every feature: it duplicated the engine's algorithm.)

Solver contract (what :func:`solve` guarantees for every run of the batch):

1. Along flows the state follows ``flow`` with an embedded Runge--Kutta pair
   (``SolverOptions.method``) under local error control (``rtol``, ``atol``).
2. Every event function is evaluated at the start, at ``event_samples - 1`` interior
   points (on the method's own dense output) and at the end of every accepted step, so
   an excursion above zero longer than ``step / event_samples`` is never missed; a
   parabola through three samples predicts the peak at each negative interior local
   maximum and at a step end the samples rise towards, and a predicted peak ``>= 0``
   inside the step is probed too (:mod:`etobs.hybrid.peaks`): a shorter excursion is
   found wherever its peak lies in the step when the event function is close to a
   parabola over those samples.
3. The first crossing is located by bracketing root finding on the dense output to a
   bracket of width ``event_xtol`` in time; the event time reported is the right end,
   where the event function is ``>= 0``, and the state there comes from the dense output.
4. At an event every rule with ``g_k >= 0`` jumps once, in rule order, each with its own
   ``j``; the event functions are then evaluated again and the jumps repeat until all
   are negative (bounded by ``max_jumps``).
5. A run ends, in bounded time, with status ``completed`` at ``t_end`` or with a failure
   status of its own (``zeno`` when its jumps pile up in time, :mod:`etobs.hybrid.zeno`;
   ``max_jumps``, ``max_steps``, ``nonfinite``, ``step_underflow``, ``model_error``);
   other runs go on. Nothing raises from inside the numerics.
6. User functions receive read-only arrays; their results are checked (shape, and NaN
   for event functions) at every call.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from etobs.errors import InputError
from etobs.hybrid.checks import check_backend
from etobs.hybrid.options import SaveAt, SolverOptions, checked_options, checked_save
from etobs.hybrid.solution import HybridSolution
from etobs.hybrid.system import BatchedSystem, HybridSystem


def solve(
    system: HybridSystem | BatchedSystem,
    x0: Any,
    t_span: Any,
    *,
    options: SolverOptions | None = None,
    save: SaveAt | None = None,
    backend: str = "auto",
    progress: Callable[[float], object] | None = None,
) -> HybridSolution:
    """Solve a batch of runs of a hybrid system (the front door of :mod:`etobs.hybrid`).

    Parameters
    ----------
    system : HybridSystem
        Written for one run (see :class:`~etobs.hybrid.HybridSystem`).
    x0 : array_like, shape (n,) or (B, n)
        Initial state of each run.
    t_span : (float, float)
        Start and end time, common to all runs.
    options : SolverOptions, optional
    save : SaveAt, optional
        What to keep (default: the full hybrid arcs).
    backend : {"auto", "engine", "scipy"}
        ``"auto"`` and ``"engine"``: the compiled engine (:mod:`etobs.hybrid.compiled`)
        for a :class:`HybridSystem`; ``"scipy"``: the ``solve_ivp`` reference, which calls
        the Python functions as they are (``"auto"`` takes it for a
        :class:`BatchedSystem`). Both follow the contract in the module docstring.
    progress : callable, optional
        Called as ``progress(k)`` with the runs done since the last call; the calls sum
        to ``B`` (pass a tqdm bar's ``update``). The reference reports each run as it
        ends; the engine every 0.2 s, a run that has reached ``t`` counting ``(t - t0) /
        (t_end - t0)`` (a float). The numbers do not depend on it.

    Returns
    -------
    HybridSolution

    Examples
    --------
    A bouncing ball, ``x = (height, velocity)``, restitution 0.5:

    >>> import numpy as np
    >>> from etobs.hybrid import HybridSystem, solve
    >>> ball = HybridSystem(
    ...     n=2, n_rules=1,
    ...     flow=lambda t, x: np.array([x[1], -9.81]),
    ...     guard=lambda t, x: np.array([-x[0] if x[1] < 0 else -1.0]),
    ...     jump=lambda k, t, x: np.array([0.0, -0.5 * x[1]]),
    ... )
    >>> [round(float(solve(ball, [1.0, 0.0], (0.0, 1.0), backend=b).jumps.t[0]), 6)
    ...  for b in ("engine", "scipy")]  # sqrt(2 / 9.81)
    [0.451524, 0.451524]

    """
    backend = check_backend(backend)
    options, save = checked_options(options), checked_save(save)
    if isinstance(system, HybridSystem) and backend != "scipy":
        from etobs.hybrid.compiled import solve_compiled

        params = system.params if system.params.size else None
        return solve_compiled(
            system.compiled(), x0, t_span, params=params, options=options, save=save, progress=progress
        )
    if isinstance(system, BatchedSystem) and backend == "engine":
        raise InputError("backend='engine' needs a HybridSystem written for one run; got a BatchedSystem")
    from etobs.hybrid.reference import solve_reference

    return solve_reference(system, x0, t_span, options=options, save=save, progress=progress)
