"""Plants from python-control systems: ``control.StateSpace`` and ``control.NonlinearIOSystem``.

python-control writes a continuous-time system as ``x' = updfcn(t, x, u, params)``,
``y = outfcn(t, x, u, params)`` with **one** input vector ``u`` and a ``params`` dict. etobs's
plant (eq. (2)) is ``x' = f_p(t, x, u, v)``, ``y = h(x)`` with the known input ``u`` and the
unknown disturbance ``v`` apart, and an output that depends on the state alone. The
conventions are mapped as follows (``docs/models.md``):

* **inputs**: ``disturbances`` names the system's inputs that are etobs's ``v`` (by
  index or by label, ``sys.input_labels``), in that order; the others are etobs's ``u``,
  in the system's order;
* **outputs**: ``outputs`` names the system's outputs that are etobs's ``y`` (default:
  all, in order); ``y_k`` is output ``outputs[k]``, and nodes name ``y`` by these ``k``;
* **params**: the system's ``params`` dict, updated by ``params`` (as python-control's
  simulation functions do), becomes the plant's parameter vector, one real number per
  key in the dict's order; the plant's functions rebuild the dict from it, so other
  values of the same keys reuse the compiled model;
* **time**: continuous-time only (``sys.dt`` 0, or ``None``, python-control's
  unspecified timebase, which it simulates as continuous);
* **output**: ``h(x)`` has no ``t`` or ``u``: a ``StateSpace`` must have ``D = 0`` on the
  chosen outputs, and a ``NonlinearIOSystem``'s ``outfcn`` is checked at construction not
  to depend on them.

A ``StateSpace`` becomes :func:`~etobs.model.linear.linear_plant` (its matrices are the
plant's ``params``). A ``NonlinearIOSystem``'s ``updfcn`` and ``outfcn`` are called by the
plant's functions; the engine compiles them with numba when they are numpy or ``math``
code that reads ``params`` by key (``params["mu"]``, ``params.get("mu", 1.0)``): inside
compiled code ``params`` is a numba typed dict from ``str`` to ``float``. An
``InterconnectedSystem`` (which runs python-control's own code) or a method as ``updfcn``
cannot be compiled, which is known from the system: ``simulate``'s ``backend="auto"`` runs
those on the scipy reference and its ``backend_reason`` says why. Other functions numba
cannot compile (any Python) are a ``ModelError`` naming ``f_p`` (and the system's ``updfcn``
and name) when the engine runs, as for any plant; ``backend="scipy"`` runs them as written.

python-control is an optional dependency (``pip install 'etobs[control]'``), imported
only when a system is converted.
"""

from __future__ import annotations

import types
from collections.abc import Callable
from dataclasses import replace
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.compile.functions import ORIGIN
from etobs.errors import InputError, InputTypeError, ModelError
from etobs.model.linear import check_no_feedthrough, linear_plant
from etobs.model.plant import Plant

#: The attribute of a plant's ``f_p`` that says why the engine cannot compile it
#: (read by :func:`etobs.estimation.compiled.engine_support`).
PYTHON_ONLY = "etobs_python_only"


def python_control_plant(
    sys: Any,
    *,
    disturbances: Any = (),
    outputs: Any = None,
    params: dict[str, Any] | None = None,
    name: str | None = None,
) -> Plant:
    """An etobs :class:`~etobs.model.plant.Plant` from a python-control system.

    Parameters
    ----------
    sys : control.StateSpace or control.NonlinearIOSystem
        A continuous-time system (module docstring for the conventions).
    disturbances : sequence of int or str, optional
        The system's inputs that are the unknown disturbance ``v``, by index or by label
        (``sys.input_labels``), in the order of ``v``; the other inputs are the known
        input ``u``, in the system's order. Default: none (every input is known).
    outputs : sequence of int or str, optional
        The system's outputs that are ``y`` (by index or label), in the order of ``y``.
        Default: all of them, in order.
    params : dict, optional
        Values of a ``NonlinearIOSystem``'s parameters, updating ``sys.params`` (keys the
        system does not list are added: its functions may read them with ``.get``). Each
        value must be a real number.
    name : str, optional
        Default: ``sys.name``.

    Returns
    -------
    Plant

    Raises
    ------
    ImportError
        python-control is not installed.
    InputTypeError
        ``sys`` is not a state-space or nonlinear I/O system.
    InputError
        A discrete-time system, an unknown input or output, a feedthrough ``D`` or an
        ``outfcn`` that depends on ``t`` or ``u``, a parameter that is not a real number.
    ModelError
        ``updfcn`` or ``outfcn`` raised or returned the wrong length when probed.

    Examples
    --------
    >>> import control
    >>> sys = control.ss([[0, 1], [-2, -0.5]], [[0, 0], [1, 0.3]], [[1, 0]], 0, inputs=["force", "wind"])
    >>> plant = python_control_plant(sys, disturbances=["wind"])
    >>> (plant.n_x, plant.n_u, plant.n_v, plant.n_y)
    (2, 1, 1, 1)

    """
    ct = _control()
    if isinstance(sys, ct.TransferFunction):
        raise InputTypeError(
            "`sys` is a control.TransferFunction; etobs needs a state-space model: pass control.ss(sys)"
        )
    if not isinstance(sys, ct.NonlinearIOSystem):
        raise InputTypeError(
            f"`sys` must be a control.StateSpace or control.NonlinearIOSystem; got {type(sys).__name__}"
        )
    if sys.dt not in (0, None):
        raise InputError(
            f"`sys` must be continuous-time (dt = 0); got dt = {sys.dt!r}, a discrete-time system. "
            "etobs's plant is the differential equation x' = f_p(t, x, u, v) (eq. (2))"
        )
    if not sys.nstates:
        raise InputError(
            f"`sys` must have at least one state; {sys.name!r} has nstates = {sys.nstates} "
            "(create it with states=n or a list of state names)"
        )
    in_labels, out_labels = _labels(sys, params)
    dist = _indices("disturbances", disturbances, in_labels, "input", allow_empty=True)
    known = tuple(k for k in range(len(in_labels)) if k not in dist)
    outs = (
        tuple(range(len(out_labels)))
        if outputs is None
        else _indices("outputs", outputs, out_labels, "output", allow_empty=False)
    )
    name = sys.name if name is None else name
    if isinstance(sys, ct.StateSpace):
        if params:
            raise InputError(
                "`params` applies to a NonlinearIOSystem; a StateSpace's numbers are its matrices; "
                f"got {params!r}"
            )
        A, B, C, D = (np.asarray(m, dtype=float) for m in (sys.A, sys.B, sys.C, sys.D))
        free = [out_labels[k] for k in range(D.shape[0]) if not D[k].any()]
        hint = (
            f", or choose the outputs without feedthrough: outputs={free}"
            if free
            else " (every output of the system has feedthrough)"
        )
        check_no_feedthrough("D", D[list(outs), :], [out_labels[k] for k in outs], in_labels, hint)
        plant = linear_plant(A, B[:, list(known)], C[list(outs), :], E=B[:, list(dist)], name=name)
    else:
        plant = _nonlinear_plant(sys, known, dist, outs, params, name)
    return replace(plant, **_names(sys, in_labels, out_labels, known, outs))  # type: ignore[arg-type]


def _names(
    sys: Any, in_labels: list[str], out_labels: list[str], known: tuple[int, ...], outs: tuple[int, ...]
) -> dict[str, tuple[str, ...] | None]:
    """The system's state, output and known-input labels as the plant's names, where the user gave them.

    python-control labels what the user left unnamed ``x[0]``, ``y[0]``, ``u[0]``; those
    stay unnamed (the plots then show ``x_1``, as for any plant).
    """

    def given(labels: list[str], letter: str) -> tuple[str, ...] | None:
        default = [f"{letter}[{k}]" for k in range(len(labels))]
        return tuple(labels) if labels and labels != default else None

    states = given(list(sys.state_labels), "x")
    outputs = given(out_labels, "y")
    inputs = given(in_labels, "u")
    return {
        "state_names": states,
        "output_names": None if outputs is None else tuple(outputs[k] for k in outs),
        "input_names": None if inputs is None else tuple(inputs[k] for k in known) or None,
    }


def _labels(sys: Any, params: dict[str, Any] | None) -> tuple[list[str], list[str]]:
    """The system's input and output labels; python-control's default ``u[k]``, ``y[k]`` for sizes left open.

    python-control lets a ``NonlinearIOSystem`` leave its number of inputs (then none) and of
    outputs (then what ``outfcn`` returns) unspecified.
    """
    inputs = list(sys.input_labels) if sys.ninputs is not None else []
    if sys.noutputs is not None:
        return inputs, list(sys.output_labels)
    merged = {**sys.params, **(params if isinstance(params, dict) else {})}
    y = _call(
        f"the outfcn of {sys.name!r}", sys.outfcn, 0.0, np.zeros(sys.nstates), np.zeros(len(inputs)), merged
    )
    return inputs, [f"y[{k}]" for k in range(np.ravel(y).size)]


def _nonlinear_plant(
    sys: Any,
    known: tuple[int, ...],
    dist: tuple[int, ...],
    outs: tuple[int, ...],
    params: dict[str, Any] | None,
    name: str,
) -> Plant:
    """The plant of a ``NonlinearIOSystem`` (module docstring), probed at construction."""
    if params is not None and not isinstance(params, dict):
        raise InputTypeError(f"`params` must be a dict of parameter values; got {type(params).__name__}")
    merged = {**sys.params, **(params or {})}
    keys = tuple(merged)
    for key in keys:
        if not isinstance(key, str):
            raise InputTypeError(f"`params` keys must be strings (names); got {key!r}")
    values = np.array([v.real(f"params[{key!r}]", merged[key]) for key in keys], dtype=float)
    _register_params_dict()
    n_in = len(known) + len(dist)
    f_p, h = _functions(sys.updfcn, sys.outfcn, n_in, known, dist, keys, outs)
    n_x = sys.nstates
    plant = Plant(
        f_p=f_p if keys else _without_params(f_p, 4),
        h=h if keys else _without_params(h, 1),
        n_x=n_x,
        n_y=len(outs),
        n_u=len(known),
        n_v=len(dist),
        name=name,
        params=values if keys else None,
    )
    _probe(sys, plant, merged, outs, n_in)
    for fn, what in ((plant.f_p, "updfcn"), (plant.h, "outfcn")):
        code = getattr(sys, what)
        if code is not None:  # a compile error then names the system's function, not only etobs's wrapper
            label = getattr(code, "__name__", type(code).__name__)
            setattr(fn, ORIGIN, f"it runs the {what} {label!r} of the python-control system {sys.name!r}")
    why = _python_only(sys)
    if why:  # the engine cannot compile it: simulate's "auto" runs the reference and says why
        setattr(plant.f_p, PYTHON_ONLY, why)
    return plant


def _python_only(sys: Any) -> str:
    """Why numba cannot compile the system's functions, known from their kind alone (``""``: it may)."""
    if isinstance(sys, _control().InterconnectedSystem):
        return (
            "is a python-control InterconnectedSystem, whose update runs python-control's own Python "
            "code, which numba cannot compile"
        )
    for what in ("updfcn", "outfcn"):
        fn = getattr(sys, what)
        if fn is not None and not isinstance(fn, types.FunctionType) and not hasattr(fn, "py_func"):
            return f"has an {what} that is a {type(fn).__name__}, not a function, which numba cannot compile"
    return ""


def _functions(
    updfcn: Callable[..., Any],
    outfcn: Callable[..., Any] | None,
    n_in: int,
    known: tuple[int, ...],
    dist: tuple[int, ...],
    keys: tuple[str, ...],
    outs: tuple[int, ...],
) -> tuple[Callable[..., np.ndarray], Callable[..., np.ndarray]]:
    """``f_p(t, x, u, v, p)`` and ``h(x, p)`` calling the system's functions (module docstring)."""
    iu = np.array(known, dtype=np.int64)
    iv = np.array(dist, dtype=np.int64)
    io = np.array(outs, dtype=np.int64)

    def f_p(t: float, x: np.ndarray, u: np.ndarray, w: np.ndarray, p: np.ndarray) -> np.ndarray:
        # python-control accepts any array_like of n_x numbers, as np.asarray(...).reshape(-1)
        return np.ravel(np.asarray(updfcn(t, x, system_input(u, w, n_in, iu, iv), params_dict(p, keys))))

    if outfcn is None:  # python-control's default output: the state

        def h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
            return x[io]

    else:

        def h(x: np.ndarray, p: np.ndarray) -> np.ndarray:
            # t = 0 and u = 0: the output was checked not to depend on them (_probe)
            y = np.ravel(np.asarray(outfcn(0.0, x, np.zeros(n_in), params_dict(p, keys))))
            return y[io]

    return f_p, h


def system_input(u: np.ndarray, w: np.ndarray, n_in: int, iu: np.ndarray, iv: np.ndarray) -> np.ndarray:
    """python-control's input vector: etobs's ``u`` at the indices ``iu``, ``v`` (here ``w``) at ``iv``."""
    out = np.empty(n_in)
    for k in range(iu.size):
        out[iu[k]] = u[k]
    for k in range(iv.size):
        out[iv[k]] = w[k]
    return out


class _ParamsDict:
    """``params_dict(p, keys) = {keys[k]: p[k]}``: a dict in Python, a typed dict in numba code.

    A plain dict costs 0.2 us in Python, a numba typed dict 40 us (measured), so the
    Python call (the scipy reference) builds a plain dict and compiled code a typed
    ``str -> float`` dict (:func:`_register_params_dict`).
    """

    def __call__(self, p: np.ndarray, keys: tuple[str, ...]) -> dict[str, float]:
        return {key: float(p[k]) for k, key in enumerate(keys)}

    def __repr__(self) -> str:
        # the compile cache's key reads this (etobs.compile.fingerprint): no address in it
        return "etobs.model.python_control.params_dict"

    def __reduce__(self) -> tuple[Callable[[], _ParamsDict], tuple[()]]:
        # a plant's functions sent to another process by value (cloudpickle, as dask does)
        # carry this object: numba there must know it before it compiles them
        return _registered_params_dict, ()


params_dict = _ParamsDict()
_REGISTERED: list[bool] = []


def _register_params_dict() -> None:
    """Teach numba :data:`params_dict` (once; numba is imported only now)."""
    if _REGISTERED:
        return
    from numba.core import types as nt
    from numba.extending import overload
    from numba.typed import Dict

    @overload(params_dict)
    def _typed(p: Any, keys: Any) -> Any:
        if len(keys) == 0:

            def empty(p: Any, keys: Any) -> Any:
                return Dict.empty(key_type=nt.unicode_type, value_type=nt.float64)

            return empty

        def filled(p: Any, keys: Any) -> Any:
            d = Dict.empty(key_type=nt.unicode_type, value_type=nt.float64)
            for k in range(len(keys)):
                d[keys[k]] = p[k]
            return d

        return filled

    _REGISTERED.append(True)


def _registered_params_dict() -> _ParamsDict:
    """:data:`params_dict`, taught to numba (how it is unpickled)."""
    _register_params_dict()
    return params_dict


_NO_PARAMS = np.zeros(0)


def _without_params(fn: Callable[..., np.ndarray], n_args: int) -> Callable[..., np.ndarray]:
    """``fn`` without its last argument ``p`` (a plant without ``params`` is called without it)."""
    if n_args == 4:

        def f_p(t: float, x: np.ndarray, u: np.ndarray, w: np.ndarray) -> np.ndarray:
            return fn(t, x, u, w, _NO_PARAMS)

        return f_p

    def h(x: np.ndarray) -> np.ndarray:
        return fn(x, _NO_PARAMS)

    return h


#: Where the output map is probed: states, times and inputs (fixed, so errors repeat).
_PROBE_T = (0.0, 0.7, 3.1)


def _probe(sys: Any, plant: Plant, merged: dict[str, float], outs: tuple[int, ...], n_in: int) -> None:
    """Call the plant's functions once, and check the output does not depend on ``t`` or ``u``.

    Raises
    ------
    ModelError
        A function raised or returned the wrong length.
    InputError
        ``outfcn`` depends on ``t`` or ``u`` (etobs's ``y = h(x)``, eq. (2)).

    """
    rng = np.random.default_rng(0)
    states = [np.zeros(plant.n_x), *rng.uniform(-1.5, 1.5, (2, plant.n_x))]
    for x in states:
        dx = _call(
            f"the updfcn of {sys.name!r}", plant.call_f_p, 0.0, x, np.zeros(plant.n_u), np.zeros(plant.n_v)
        )
        if dx.shape != (plant.n_x,):
            raise ModelError(
                f"the updfcn of {sys.name!r} returned shape {dx.shape}; expected ({plant.n_x},) (nstates)"
            )
        y = _call(f"the outfcn of {sys.name!r}", plant.call_h, x)
        if y.shape != (plant.n_y,):
            raise ModelError(
                f"the outfcn of {sys.name!r} gave outputs of shape {y.shape}; expected ({plant.n_y},)"
            )
        if sys.outfcn is None:
            continue
        for t in _PROBE_T:
            for u in (np.zeros(n_in), np.ones(n_in), rng.uniform(-2.0, 2.0, n_in)):
                other = _call(f"the outfcn of {sys.name!r}", sys.outfcn, t, x, u, dict(merged))
                other = np.ravel(np.asarray(other, dtype=float))[list(outs)]
                if not np.array_equal(other, y):
                    raise InputError(
                        f"the outfcn of `sys` ({sys.name!r}) depends on t or u: at x = {x.round(3).tolist()} "
                        f"it gives {y.tolist()} at t = 0, u = 0 and {other.tolist()} at t = {t:g}, "
                        f"u = {u.round(3).tolist()}; etobs's output is y = h(x) (eq. (2)). Choose `outputs` "
                        "that depend on the state only, or make the input a state"
                    )


def _call(what: str, fn: Callable[..., Any], *args: Any) -> np.ndarray:
    """``fn(*args)`` as a float array; a ModelError naming ``what`` when it raises."""
    try:
        return np.asarray(fn(*args), dtype=float)
    except Exception as exc:  # the user's code may raise anything; say whose it is
        raise ModelError(f"{what} raised {type(exc).__name__}: {exc}") from exc


def _indices(name: str, value: Any, labels: list[str], what: str, *, allow_empty: bool) -> tuple[int, ...]:
    """Indices of a system's signals named by index or label; distinct, in the order given."""
    if isinstance(value, str | int | np.integer):
        value = (value,)
    try:
        items = list(value)
    except TypeError as exc:
        raise InputTypeError(
            f"`{name}` must be a sequence of {what} indices or labels; got {v.shown(value)}"
        ) from exc
    if not items and not allow_empty:
        raise InputError(f"`{name}` must name at least one {what}; got an empty sequence")
    out = []
    for k, item in enumerate(items):
        if isinstance(item, str):
            if item not in labels:
                raise InputError(f"`{name}[{k}]` = {item!r} is not one of the system's {what}s {labels}")
            out.append(labels.index(item))
        else:
            index = v.integer(f"{name}[{k}]", item)
            if not labels:
                raise InputError(f"`{name}[{k}]` = {index} names an {what}, but the system has no {what}s")
            if not 0 <= index < len(labels):
                plural = "s" if len(labels) > 1 else ""
                raise InputError(
                    f"`{name}[{k}]` must be an {what} index in 0..{len(labels) - 1} or an {what} label "
                    f"(the system has {len(labels)} {what}{plural}: {labels}); got {index}"
                )
            out.append(index)
    if len(set(out)) != len(out):
        raise InputError(f"`{name}` must not name an {what} twice; got {items} (indices {out})")
    return tuple(out)


def _control() -> Any:
    """The ``control`` module, or an ImportError that says how to install it."""
    try:
        import control
    except ImportError as exc:
        raise ImportError("python-control plants need python-control: pip install 'etobs[control]'") from exc
    return control
