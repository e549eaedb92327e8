"""The Zeno rule: jumps piling up in time end a run with status ``zeno``.

A total count (``SolverOptions(max_jumps=...)``) stops a Zeno run only after it has
spent the whole budget on jumps at one instant (a bouncing ball: a million jumps, over
an hour on the retired numpy solver). Zeno behaviour is a *density*: infinitely many
jumps in a finite time, so the time between jumps falls below anything the solver can
resolve (the event time accuracy ``event_xtol`` and the floating-point resolution of
``t``). The rule counts the jumps of a run in windows of time:

* a jump at ``t`` joins the current window when ``t - start <= span * max(1, |t|)``,
  else it opens a new window at ``t``;
* the run stops with ``zeno`` when a window holds more than ``zeno_jumps`` jumps.

So a run stops when more than ``2 * zeno_jumps`` jumps fall in any interval of length
``span * max(1, |t|)``, and never when every such interval holds at most
``zeno_jumps``. With the defaults (1000 jumps within ``1e-7 * max(1, |t|)`` s) the
jumps are then on average less than ``1e-10 max(1, |t|)`` s apart: a hundred times the
default event accuracy (``event_xtol = 1e-12``), below which the solvers no longer
place events where they are (the engine placed the resets of a clock of period
``1e-13`` s every ``4.4e-11`` s, the reference every ``1e-13`` to ``3.5e-13`` s).

:func:`zeno_window` is the one definition: plain scalar Python that the engine's
kernel compiles and the scipy reference runs as is.
"""

from __future__ import annotations


def zeno_window(t: float, start: float, count: int, span: float) -> tuple[float, int]:
    """The window ``(start, count)`` after a jump at ``t`` (module docstring).

    ``start`` is ``-inf`` before the first jump; ``span`` is ``SolverOptions.zeno_span``.
    """
    if t - start <= span * max(1.0, abs(t)):
        return start, count + 1
    return t, 1
