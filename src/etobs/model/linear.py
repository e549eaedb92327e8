"""Linear plants and observers from matrices: ``x' = A x + B u + E v``, ``y = C x`` (eq. (2)).

The matrices travel as the model's ``params`` (:class:`~etobs.model.plant.Plant`), not as
constants in its code: the functions here depend only on the dimensions, so the engine
compiles them once per shape, and a plant with other matrices of the same shape reuses
the compiled model (etobs reads ``params`` from the run's parameter vector).

The parameter vector is the matrices flattened row by row (C order), one after the other:
``(A, B, E, C)`` for :func:`linear_plant` and ``(A, B, L)`` for :func:`linear_luenberger`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
from numpy.typing import NDArray

from etobs import _validate as v
from etobs.errors import InputError
from etobs.model.observer import Observer, with_gain
from etobs.model.plant import Plant


def linear_plant(
    A: Any,
    B: Any = None,
    C: Any = None,
    D: Any = None,
    *,
    E: Any = None,
    name: str = "linear plant",
    **names_and_units: Any,
) -> Plant:
    """The plant ``x' = A x + B u + E v``, ``y = C x`` (eq. (2) with linear ``f_p`` and ``h``).

    Parameters
    ----------
    A : array_like, shape (n_x, n_x)
    B : array_like, shape (n_x, n_u), optional
        Known-input matrix (default: no known input, ``n_u = 0``).
    C : array_like, shape (n_y, n_x), optional
        Output matrix (default: the identity, ``y = x``, as python-control's default
        output).
    D : array_like, shape (n_y, n_u), optional
        Feedthrough; only ``None`` or zeros are accepted: the paper's output map is
        ``y = h(x)`` (eq. (2)), which has no term in ``u``.
    E : array_like, shape (n_x, n_v), optional
        Disturbance matrix (default: no disturbance, ``n_v = 0``).
    name : str
    **names_and_units
        ``state_names``, ``state_units``, ``output_names``, ``output_units``,
        ``input_names``, ``input_units``, as for :class:`~etobs.model.Plant`.

    Returns
    -------
    Plant
        With ``params`` the matrices ``(A, B, E, C)`` flattened (module docstring).

    Raises
    ------
    InputError
        A matrix of the wrong shape (the message names it, the expected and the received
        shape) or a nonzero ``D``.

    Examples
    --------
    >>> import numpy as np
    >>> plant = linear_plant([[0.0, 1.0], [-2.0, -0.5]], B=[[0.0], [1.0]], C=[[1.0, 0.0]])
    >>> (plant.n_x, plant.n_u, plant.n_v, plant.n_y)
    (2, 1, 0, 1)
    >>> plant.call_f_p(0.0, np.array([1.0, 2.0]), np.array([3.0]), np.zeros(0)).tolist()
    [2.0, 0.0]
    >>> plant.call_h(np.array([1.0, 2.0])).tolist()
    [1.0]

    """
    a = _square("A", A)
    n_x = a.shape[0]
    b = _block("B", B, (n_x, None))
    e = _block("E", E, (n_x, None))
    c = np.eye(n_x) if C is None else v.matrix("C", C, (None, n_x))
    if c.shape[0] == 0:
        raise InputError(f"`C` must have at least one row (one output); got shape {c.shape}")
    if D is not None:
        check_no_feedthrough("D", v.matrix("D", D, (c.shape[0], b.shape[1])))
    n_u, n_v, n_y = b.shape[1], e.shape[1], c.shape[0]
    f_p = affine_field(n_x, n_u, n_v)
    offset = a.size + b.size + e.size

    def h(x: NDArray[np.float64], p: NDArray[np.float64]) -> NDArray[np.float64]:
        # y = C x: C is the last block of p
        return p[offset : offset + n_y * n_x].reshape((n_y, n_x)) @ x

    params = np.concatenate([a.ravel(), b.ravel(), e.ravel(), c.ravel()])
    return Plant(
        f_p=f_p, h=h, n_x=n_x, n_y=n_y, n_u=n_u, n_v=n_v, name=name, params=params, **names_and_units
    )


def linear_luenberger(A: Any, L: Any, B: Any = None, *, name: str = "luenberger") -> Observer:
    """The Luenberger observer ``xhat' = A xhat + B u + L (ybar - yhat)`` with ``z = xhat``.

    :func:`~etobs.model.observer.luenberger` for the linear model ``f(t, x, u) = A x +
    B u``, with the matrices as ``params`` (module docstring), so that another gain of the
    same shape reuses the compiled model. ``yhat = h(xhat)`` is the plant's output map, as
    in eq. (7).

    Parameters
    ----------
    A : array_like, shape (n_x, n_x)
    L : array_like, shape (n_x, n_y)
        Observer gain.
    B : array_like, shape (n_x, n_u), optional
        Known-input matrix (default: no known input).
    name : str

    Returns
    -------
    Observer
        With ``n_z = n_x`` and ``params`` the matrices ``(A, B, L)`` flattened.

    Examples
    --------
    >>> import numpy as np
    >>> obs = linear_luenberger([[0.0, 1.0], [-2.0, -0.5]], L=[[2.0], [1.0]])
    >>> obs.call_f_o(0.0, np.array([1.0, 0.0]), np.zeros(0), np.array([3.0]), np.array([1.0])).tolist()
    [4.0, 0.0]

    """
    a = _square("A", A)
    n_x = a.shape[0]
    b = _block("B", B, (n_x, None))
    gain = v.matrix("L", L, (n_x, None))
    if gain.shape[1] == 0:
        raise InputError(f"`L` must have at least one column (one output); got shape {gain.shape}")
    field = affine_field(n_x, b.shape[1], gain.shape[1])

    def f_o(
        t: float, z: np.ndarray, u: np.ndarray, ybar: np.ndarray, yhat: np.ndarray, p: np.ndarray
    ) -> np.ndarray:
        # A z + B u + L (ybar - yhat): the affine field with L in E's place
        return field(t, z, u, ybar - yhat, p)

    params = np.concatenate([a.ravel(), b.ravel(), gain.ravel()])
    return with_gain(Observer(f_o=f_o, n_z=n_x, name=name, params=params), gain)


def affine_field(n_x: int, n_u: int, n_v: int) -> Callable[..., np.ndarray]:
    """``f(t, x, u, v, p) = A x + B u + E v``, with ``A, B, E`` the first blocks of ``p``.

    One run, 1-D arrays; numpy only, so that numba compiles it. The dimensions are the
    only constants in its code (module docstring).
    """
    nb, ne = n_x * n_u, n_x * n_v
    na = n_x * n_x

    def f(
        t: float,
        x: NDArray[np.float64],
        u: NDArray[np.float64],
        w: NDArray[np.float64],
        p: NDArray[np.float64],
    ) -> NDArray[np.float64]:
        dx = p[0:na].reshape((n_x, n_x)) @ x
        if n_u:
            dx = dx + p[na : na + nb].reshape((n_x, n_u)) @ u
        if n_v:
            dx = dx + p[na + nb : na + nb + ne].reshape((n_x, n_v)) @ w
        return dx

    return f


def check_no_feedthrough(
    name: str,
    D: np.ndarray,
    outputs: list[str] | None = None,
    inputs: list[str] | None = None,
    hint: str = "",
) -> None:
    """Refuse a nonzero feedthrough ``D``: eq. (2)'s output ``y = h(x)`` has no term in ``u``.

    ``outputs`` and ``inputs`` label ``D``'s rows and columns in the message (a
    python-control system's signal names); ``hint`` ends it.

    Raises
    ------
    InputError
        Naming ``name``, what is expected and where ``D`` is nonzero.

    """
    nonzero = np.argwhere(D != 0)
    if nonzero.size:
        where = [tuple(int(i) for i in ij) for ij in nonzero[:4]]
        more = f" and {len(nonzero) - 4} more" if len(nonzero) > 4 else ""
        if outputs is not None and inputs is not None:
            pairs = ", ".join(f"output {outputs[i]!r} on input {inputs[j]!r}" for i, j in where)
            more = f" ({pairs}{more})"
        raise InputError(
            f"`{name}` must be zero: etobs's output map is y = h(x) (eq. (2)), with no feedthrough "
            f"from the inputs; got {name} of shape {D.shape} with nonzero entries at {where}{more} "
            f"(max |{name}| = {np.abs(D).max():g}). Model the feedthrough as a state or measure "
            f"y - D u instead{hint}"
        )


def _square(name: str, value: Any) -> np.ndarray:
    """A finite square matrix with at least one row."""
    arr = v.matrix(name, value, (None, None))
    if arr.shape[0] != arr.shape[1] or arr.shape[0] == 0:
        raise InputError(f"`{name}` has shape {arr.shape}; expected a square (n_x, n_x) matrix with n_x >= 1")
    return arr


def _block(name: str, value: Any, shape: tuple[int, None]) -> np.ndarray:
    """An input matrix of ``shape`` (no columns when ``value`` is ``None``)."""
    if value is None:
        return np.zeros((shape[0], 0))
    return v.matrix(name, value, shape)
