"""The peak probe: where a parabola through the samples of a step predicts an excursion.

Both solvers sample each event function on every accepted step at ``θ = i/S``,
``i = 0 .. S`` (``S = event_samples``; ``θ = 0`` is the step start, ``θ = 1`` its end),
so an excursion above zero longer than ``1/S`` of the step is never missed. A shorter
one can fall between two samples. Near a smooth maximum the event function is close
to a parabola, so the parabola through the three samples around the largest one
predicts the peak, and a predicted peak ``>= 0`` is probed: the event function is
evaluated there too, and the sign test then sees the excursion if the prediction was
right.

The vertex of the parabola through samples ``i - 1, i, i + 1`` lies within half a
sub-interval of sample ``i`` exactly when sample ``i`` is the largest of the three, so
an interior maximum covers the peaks in ``[(i - 1/2)/S, (i + 1/2)/S]``, and the steps'
first and last half sub-intervals are covered by their end samples:

* **inside**: a negative interior local maximum, ``g_{i-1} < g_i >= g_{i+1}``;
* **start**: ``g_0 >= g_1``, the event function falling at the step start; the
  parabola through samples ``0, 1, 2`` then has its vertex at ``θ <= 1/(2S)``, probed
  when it lies inside the step (the previous step ended at ``θ = 0`` with ``g < 0``,
  but an excursion may lie between it and the first sample);
* **end**: ``g_S > g_{S-1}``, rising at the step end; the parabola through samples
  ``S - 2, S - 1, S`` has its vertex at ``θ > 1 - 1/(2S)``, probed when it is before
  the end (one that lies after the end is the next step's start candidate).

Each kind gives at most one probe per step (the earliest over the event functions), so
the probes at the start and end only add candidate times to the interior one.

:func:`peak_probes` is the one definition: plain scalar Python that the engine's
kernel compiles and the scipy reference runs as is (as :mod:`etobs.hybrid.zeno`).
"""

from __future__ import annotations

import math
from collections.abc import Sequence


def peak_probes(seq: Sequence[float], S: int) -> tuple[float, float, float]:
    """θ of the probes of one event function on one step: ``(start, inside, end)``.

    Parameters
    ----------
    seq : sequence of float, length >= S + 1
        The event function at ``θ = i/S``, ``i = 0 .. S`` (module docstring).
    S : int
        ``event_samples``; below 2 there are no three samples to fit, and no probe.

    Returns
    -------
    (float, float, float)
        The θ of the predicted peak ``>= 0`` at the step start (in ``(0, 1/(2S)]``),
        at the earliest negative interior maximum and at the step end (in
        ``(1 - 1/(2S), 1)``); NaN where there is none. A NaN sample compares false
        and gives no probe (the solvers end the run on it).

    """
    start = inside = end = math.nan
    for c in range(1, S):  # the parabola through samples c - 1, c, c + 1
        left, mid, right = seq[c - 1], seq[c], seq[c + 1]
        at_start = c == 1 and left < 0.0 and left >= mid
        # the first maximum with a peak >= 0 is the earliest: its vertex is within half a
        # sub-interval of sample c, and the next maximum is at least two samples on
        at_max = math.isnan(inside) and mid < 0.0 and mid > left and mid >= right
        at_end = c == S - 1 and right < 0.0 and right > mid
        curv = left - 2.0 * mid + right  # twice the parabola's quadratic coefficient
        if not (at_start or at_max or at_end) or not curv < 0.0:
            continue
        if mid - (right - left) ** 2 / (8.0 * curv) < 0.0:  # the value at the vertex
            continue
        theta = (c + (left - right) / (2.0 * curv)) / S  # the vertex
        if at_start and theta > 0.0:
            start = theta
        if at_max:
            inside = theta
        if at_end and theta < 1.0:
            end = theta
    return start, inside, end
