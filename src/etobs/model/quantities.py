"""Names and units of a model's quantities (states, outputs, inputs), carried to every output.

A :class:`~etobs.model.Plant` names its states ``x``, outputs ``y`` and inputs ``u``,
an :class:`~etobs.model.Observer` its state ``z``; tables, the xarray Dataset and the
plots read them from here, through :func:`quantities`. Unnamed quantities keep the
paper's symbols (``x_1``, ``y_2``) and no unit, as before names existed.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from etobs._validate import shown
from etobs.errors import InputError, InputTypeError


@dataclass(frozen=True)
class Quantity:
    """One entry of a model vector: its symbol, and its name and unit when the model gives them.

    Parameters
    ----------
    symbol : str
        The paper's symbol, 1-based: ``x_1``, ``y_2``, ``z_3``, ``u_1``.
    name : str
        The model's name for it; ``""`` when it has none.
    unit : str
        Its unit (``"rad"``, ``"m/s"``); ``""`` when none was given.

    Examples
    --------
    >>> q = Quantity("x_1", "motor angle", "rad")
    >>> q.label, q.axis_label
    ('motor angle', 'motor angle [rad]')
    >>> Quantity("x_2", "", "").label
    '$x_{2}$'

    """

    symbol: str
    name: str = ""
    unit: str = ""

    @property
    def label(self) -> str:
        """The name, or the symbol in math text (``$x_{1}$``) when there is none."""
        if self.name:
            return self.name
        letter, _, index = self.symbol.partition("_")
        return f"${letter}_{{{index}}}$"

    @property
    def axis_label(self) -> str:
        """``label [unit]``, or the label alone without a unit."""
        return with_unit(self.label, self.unit)

    @property
    def text(self) -> str:
        """Plain text for tables: the name, else the symbol (``x_1``)."""
        return self.name or self.symbol

    @property
    def described(self) -> str:
        """Plain text with the unit: ``motor angle [rad]``; ``x_1`` without name or unit."""
        return with_unit(self.text, self.unit)


def with_unit(text: str, unit: str) -> str:
    """``text [unit]``, or ``text`` alone without a unit: how etobs writes a quantity and its unit."""
    return f"{text} [{unit}]" if unit else text


def names(name: str, value: Any, size: int) -> tuple[str, ...] | None:
    """``value`` checked as ``size`` strings (names or units), or ``None`` when not given."""
    if value is None:
        return None
    if isinstance(value, str) or not isinstance(value, list | tuple):
        raise InputTypeError(
            f"`{name}` must be a list of {size} strings, one per entry; got {shown(value)} "
            f"({type(value).__name__})"
        )
    bad = [k for k, s in enumerate(value) if not isinstance(s, str)]
    if bad:
        raise InputTypeError(
            f"`{name}` must hold strings; entry {bad[0]} is {shown(value[bad[0]])} "
            f"({type(value[bad[0]]).__name__})"
        )
    if len(value) != size:
        raise InputError(f"`{name}` must have {size} entries, one per entry of the vector; got {len(value)}")
    return tuple(value)


def quantities(
    letter: str, size: int, labels: tuple[str, ...] | None, units: tuple[str, ...] | None
) -> tuple[Quantity, ...]:
    """The ``size`` entries of the vector ``letter``, with names and units where given."""
    return tuple(
        Quantity(f"{letter}_{k + 1}", labels[k] if labels else "", units[k] if units else "")
        for k in range(size)
    )
