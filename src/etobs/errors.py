"""All exceptions raised by etobs, and its one warning of its own, in one place.

Every input check raises :class:`InputError` (a :class:`ValueError`) or
:class:`InputTypeError` (a :class:`TypeError`) with a message that names the
argument, what was expected and what was received.
"""

from __future__ import annotations

import os

#: Set to ``1`` to see, under an error from compiling or calling a user function, the
#: whole chained traceback of its cause (numba's, hundreds of lines); without it the cause
#: is kept, not printed, in the exception's ``__context__``.
DEBUG_ENV = "ETOBS_DEBUG"


def debug() -> bool:
    """Whether ``$ETOBS_DEBUG`` asks for the chained tracebacks (:data:`DEBUG_ENV`)."""
    return os.environ.get(DEBUG_ENV, "").strip().lower() not in {"", "0", "off", "no", "false"}


def cause(exc: BaseException) -> BaseException | None:
    """What to chain a short error to: ``exc`` under ``$ETOBS_DEBUG``, else nothing.

    ``raise ModelError(...) from cause(exc)`` prints the one-line message alone; the
    original exception stays in ``__context__`` for a debugger or a test.
    """
    return exc if debug() else None


class EtobsError(Exception):
    """Base class of every exception raised on purpose by etobs.

    Examples
    --------
    Catch every mistake etobs reports, and only those:

    >>> import etobs
    >>> try:
    ...     etobs.Linear(-1.0)
    ... except etobs.EtobsError as exc:
    ...     print(exc)
    `a` must be > 0; got -1

    """


class InputError(EtobsError, ValueError):
    """An argument has the right type but a wrong value or shape.

    Examples
    --------
    >>> import etobs
    >>> etobs.StaticRule(gamma=etobs.Linear(1.0), eps=0.0)
    Traceback (most recent call last):
    ...
    etobs.errors.InputError: `eps` must be > 0; got 0

    """


class InputTypeError(EtobsError, TypeError):
    """An argument has the wrong type.

    Examples
    --------
    >>> import etobs
    >>> etobs.Node([0], rule="dynamic")
    Traceback (most recent call last):
    ...
    etobs.errors.InputTypeError: `rule` must be a TriggerRule (DynamicRule, StaticRule, PeriodicRule); got str

    """


class ModelError(InputError):
    """A user model function (plant, observer, rule) returned something unusable.

    Examples
    --------
    >>> import numpy as np, etobs
    >>> etobs.FunctionSignal(lambda t: np.zeros(3), dim=2)  # doctest: +ELLIPSIS
    Traceback (most recent call last):
    ...
    etobs.errors.ModelError: signal function `fn` returned shape (3,) for t = 0.0; expected (2,): ...

    """


class DesignError(EtobsError):
    """A design problem (LMI, parameter choice) has no solution, or the solver failed."""


class PerformanceWarning(RuntimeWarning):
    """etobs runs something on a slower path than it could, and says why (the numbers are the same).

    For example a model whose lane form is not vector code (docs/solver.md). Silence it
    with ``warnings.filterwarnings("ignore", category=etobs.PerformanceWarning)``.

    Examples
    --------
    >>> import warnings, etobs
    >>> issubclass(etobs.PerformanceWarning, RuntimeWarning)
    True
    >>> with warnings.catch_warnings():  # here only; filterwarnings alone: everywhere
    ...     warnings.filterwarnings("ignore", category=etobs.PerformanceWarning)
    ...     warnings.warn("a slow path", etobs.PerformanceWarning)

    """
