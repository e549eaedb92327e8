"""All exceptions raised by etobs, in one place.

Every input check raises :class:`InputError` (a :class:`ValueError`) or
:class:`InputTypeError` (a :class:`TypeError`) with a message that names the
argument, what was expected and what was received.
"""

from __future__ import annotations


class EtobsError(Exception):
    """Base class of every exception raised on purpose by etobs."""


class InputError(EtobsError, ValueError):
    """An argument has the right type but a wrong value or shape."""


class InputTypeError(EtobsError, TypeError):
    """An argument has the wrong type."""


class ModelError(InputError):
    """A user model function (plant, observer, rule) returned something unusable."""


class DesignError(EtobsError):
    """A design problem (LMI, parameter choice) has no solution, or the solver failed."""
