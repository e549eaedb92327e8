"""Per-run termination status of a hybrid simulation.

Status is data: each run of a batch carries its own status, and one run's failure
never stops the others. :func:`status_message` explains each status and how to fix it.
"""

from __future__ import annotations

import enum
from collections.abc import Mapping


class Status(enum.IntEnum):
    """How a run ended: every run ends with one of these, in bounded time (docs/solver.md).

    Examples
    --------
    >>> from etobs import Status
    >>> Status.COMPLETED.ok, Status.MAX_JUMPS.label, Status(6).label
    (True, 'max_jumps', 'zeno')

    """

    RUNNING = -1
    COMPLETED = 0
    MAX_JUMPS = 1
    MAX_STEPS = 2
    NONFINITE = 3
    STEP_UNDERFLOW = 4
    MODEL_ERROR = 5
    ZENO = 6

    @property
    def label(self) -> str:
        """Lower-case name used in files and tables, e.g. ``"max_jumps"``."""
        return self.name.lower()

    @property
    def ok(self) -> bool:
        """Whether the run reached the end of the horizon."""
        return self is Status.COMPLETED


_MESSAGES = {
    Status.RUNNING: "the run has not finished",
    Status.COMPLETED: "the run reached the end of the horizon",
    Status.MAX_JUMPS: (
        "the run reached its limit on the number of jumps before the end of the horizon: "
        "many jumps (a guard crossed often, or a state that grows without bound) rather than "
        "jumps piling up at one instant, which ends a run with `zeno`; increase "
        "`SolverOptions(max_jumps=...)` if the jumps are expected"
    ),
    Status.MAX_STEPS: (
        "the run reached the step limit before the end of the horizon: loosen `rtol`/`atol`, "
        "or increase `SolverOptions(max_steps=...)`"
    ),
    Status.NONFINITE: (
        "the state or its derivative became NaN or infinite (finite escape time, or a model "
        "function returning NaN): check the model and the initial condition"
    ),
    Status.STEP_UNDERFLOW: (
        "the step size fell below the floating-point resolution of t: the problem may be "
        "stiff or discontinuous along flows; loosen `rtol`/`atol` or check the model"
    ),
    Status.MODEL_ERROR: (
        "a model function failed: it raised an exception or returned an array of the wrong "
        "shape; run the same problem with backend='scipy' to see the Python traceback"
    ),
    Status.ZENO: (
        "the jumps piled up in time: more than `SolverOptions(zeno_jumps=...)` jumps within "
        "`zeno_span * max(1, |t|)` seconds (Zeno behaviour, or jumps closer together than the "
        "solver resolves in time). Check that every jump map leaves its guard's jump set "
        "(guard < 0 after the jump) and that the guards are not crossed ever faster, or change "
        "`zeno_jumps`/`zeno_span`"
    ),
}

#: The reference runs the Python functions as they are and its failure detail holds their
#: exception: it must not send the user to itself.
_REFERENCE_MESSAGES = {
    Status.MODEL_ERROR: (
        "a model function failed on this run's values (the reference ran it as written: the "
        "exception or the shape is the one Python gave); call it on the run's last state to "
        "reproduce it"
    ),
}


def status_message(
    status: Status,
    t: float | None = None,
    detail: str = "",
    backend: str = "",
    advice: Mapping[Status, str] | None = None,
) -> str:
    """Return a sentence describing ``status`` (with the stopping time when given).

    ``detail`` (e.g. which function failed) is put before the general explanation;
    ``backend`` is the solver that ran (``"scipy"``'s advice differs from the engine's).
    The messages speak of guards and jumps: this layer knows nothing of what they model.
    ``advice`` maps a status to a sentence that a layer above adds in its own terms
    (the estimation layer: eps, transmissions and Theorem 4 for ``zeno``).
    """
    text = _MESSAGES[Status(status)]
    if backend == "scipy":
        text = _REFERENCE_MESSAGES.get(Status(status), text)
    if detail:
        text = f"{detail}; {text}"
    extra = (advice or {}).get(Status(status))
    if extra:
        text = f"{text}. {extra}"
    if t is not None and status != Status.COMPLETED:
        return f"stopped at t={t:.6g}: {text}"
    return text
