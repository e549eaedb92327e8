"""A hybrid system in the form the solvers accept.

The system is ``x' = flow(t, x)`` while every event function is negative, and
``x+ = jump(k, t, x)`` when event function ``k`` is ``>= 0``. The solvers know nothing
else about it.

Users write :class:`HybridSystem` for one run, on 1-D arrays, like every function in
etobs; the engine compiles it (:meth:`HybridSystem.compiled`), the scipy reference calls
it as it is. :class:`BatchedSystem` is the same system with the runs on axis 0, the form
of the reference solver's model of an estimation problem (:meth:`HybridSystem.batched`
derives it).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np

from etobs import _validate as v
from etobs.compile.functions import with_params
from etobs.errors import InputError, ModelError
from etobs.hybrid.checks import check_log_columns, check_sizes

if TYPE_CHECKING:
    from etobs.hybrid.compiled import CompiledSystem

FlowFn = Callable[..., Any]
GuardFn = Callable[..., Any]
JumpFn = Callable[..., Any]


def _names(n_rules: int, rule_names: tuple[str, ...]) -> tuple[str, ...]:
    if not rule_names:
        return tuple(f"rule{k}" for k in range(n_rules))
    if len(rule_names) != n_rules:
        raise InputError(f"`rule_names` has {len(rule_names)} names; expected n_rules={n_rules}")
    return tuple(rule_names)


@dataclass(frozen=True)
class HybridSystem:
    """A hybrid system with ``n_rules`` jump rules, written for one run.

    Parameters
    ----------
    n : int
        State dimension.
    n_rules : int
        Number of jump rules (event functions).
    flow : callable
        ``flow(t, x) -> x'``: ``t`` a float, ``x`` of shape ``(n,)``; returns shape ``(n,)``.
    guard : callable
        ``guard(t, x) -> g`` of shape ``(n_rules,)``; rule ``k`` may jump where
        ``g[k] >= 0`` and the system flows while every ``g < 0``.
    jump : callable
        ``jump(k, t, x) -> x+``: rule ``k``'s jump map, shape ``(n,)``.
    rule_names : tuple of str, optional
        Names of the rules, used in messages and logs.
    n_flow : int, optional
        When given, only the entries ``0 .. n_flow-1`` change along flows; the others
        (counters, buffers, identifiers) have zero derivative. The engine then leaves them
        out of its stages, error norm and dense output (so that they do not dilute the
        tolerance), and the flow need not write them; a flow that moves one anyway ends
        the run with ``model_error``.
    params : array_like, optional
        A parameter vector passed to every function as its last argument
        (``flow(t, x, p)``, ``guard(t, x, p)``, ``jump(k, t, x, p)``); numbers kept here
        change without a recompile.
    log_columns : tuple of int, optional
        State entries kept in the jump log: at every jump, their values just after it
        (``x+[log_columns]``) become a row of ``solution.jumps.x``, named ``x_i``
        (the state at a jump is otherwise kept only with ``SaveAt(steps=True)``).

    Write the functions with numpy or ``math``: the engine compiles them (and the Python
    functions they call); they may return a 1-D array or a tuple of floats.

    Examples
    --------
    A bouncing ball, ``x = (height, velocity)``, restitution ``p[0]``:

    >>> import numpy as np
    >>> from etobs.hybrid import HybridSystem, solve
    >>> ball = HybridSystem(
    ...     n=2, n_rules=1,
    ...     flow=lambda t, x, p: np.array([x[1], -9.81]),
    ...     guard=lambda t, x, p: np.array([-x[0] if x[1] < 0 else -1.0]),
    ...     jump=lambda k, t, x, p: np.array([0.0, -p[0] * x[1]]),
    ...     params=[0.5],
    ... )
    >>> sol = solve(ball, [1.0, 0.0], (0.0, 1.0))
    >>> round(float(sol.jumps.t[0]), 6)  # sqrt(2 / 9.81)
    0.451524

    """

    n: int
    n_rules: int
    flow: FlowFn
    guard: GuardFn
    jump: JumpFn
    rule_names: tuple[str, ...] = ()
    n_flow: int | None = None
    params: Any = None
    log_columns: tuple[int, ...] = ()
    _compiled: dict[str, CompiledSystem] = field(init=False, repr=False, compare=False, default_factory=dict)

    def __post_init__(self) -> None:
        check_sizes(self.n, self.n_rules, self.n_flow)
        v.function("flow", self.flow)
        v.function("guard", self.guard)
        v.function("jump", self.jump)
        object.__setattr__(self, "rule_names", _names(self.n_rules, tuple(self.rule_names)))
        object.__setattr__(self, "params", v.params("params", self.params))
        object.__setattr__(self, "log_columns", check_log_columns(self.log_columns, self.n))

    def __getstate__(self) -> dict[str, Any]:
        return {**self.__dict__, "_compiled": {}}  # compiled functions stay in their process

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    def call_flow(self, t: float, x: np.ndarray) -> Any:
        """``flow`` of one run, with ``params`` when there are any."""
        return with_params(self.flow, self.params, t, x)

    def call_guard(self, t: float, x: np.ndarray) -> Any:
        """``guard`` of one run, with ``params`` when there are any."""
        return with_params(self.guard, self.params, t, x)

    def call_jump(self, k: int, t: float, x: np.ndarray) -> Any:
        """``jump`` of one run, with ``params`` when there are any."""
        return with_params(self.jump, self.params, k, t, x)

    def compiled(self) -> CompiledSystem:
        """The system for the engine (its functions compiled; memoized)."""
        if "engine" not in self._compiled:
            from etobs.hybrid.compiled import compile_system

            self._compiled["engine"] = compile_system(
                self.flow,
                self.guard,
                self.jump,
                self.n,
                self.n_rules,
                n_params=self.params.size,
                rule_names=self.rule_names,
                n_flow=self.n_flow,
                log_columns=self.log_columns,
            )
        return self._compiled["engine"]

    def batched(self) -> BatchedSystem:
        """The same system with the runs on axis 0 (the reference's form), run by run in Python."""
        flow = _python_rows(self.call_flow, "flow", self.n)
        guard = _python_rows(self.call_guard, "guard", self.n_rules)
        jump = _python_jump(self.call_jump, self.n)
        return BatchedSystem(
            n=self.n,
            n_rules=self.n_rules,
            flow=flow,
            guard=guard,
            jump=jump,
            rule_names=self.rule_names,
            n_flow=self.n_flow,
            log_columns=self.log_columns,
        )


def read_only(a: Any) -> Any:
    """A read-only view of an array (anything else as it is), for a user function's input.

    A function that writes into its input would change the solver's state behind its
    back (a stage of the step, the state saved before a jump): numpy then raises
    ``ValueError: assignment destination is read-only``, and the run ends with
    ``model_error`` naming the function. The engine refuses such a function when it
    compiles it (:mod:`etobs.compile.functions`).
    """
    if not isinstance(a, np.ndarray):
        return a
    view = a.view()
    view.setflags(write=False)  # half the cost of view.flags.writeable = False
    return view


def raised(name: str, exc: Exception) -> str:
    """How a failure names the Python function ``name`` that raised ``exc`` (both solvers' words)."""
    from etobs.compile.functions import WRITES_INPUT

    if isinstance(exc, ValueError) and "read-only" in str(exc):
        return f"`{name}` {WRITES_INPUT}"
    return f"`{name}` raised {type(exc).__name__}: {exc}"


def _one(name: str, out: Any, n: int) -> np.ndarray:
    arr = np.asarray(out, dtype=float)
    if arr.shape != (n,):
        raise ModelError(f"`{name}` returned shape {arr.shape} for one run; expected ({n},)")
    return arr


def _python_rows(fn: Callable[..., Any], name: str, n: int) -> Callable[[np.ndarray, np.ndarray], np.ndarray]:
    def rows(t: np.ndarray, x: np.ndarray) -> np.ndarray:
        out = np.empty((x.shape[0], n))
        for b in range(x.shape[0]):
            out[b] = _one(name, fn(float(t[b]), x[b]), n)
        return out

    return rows


def _python_jump(fn: Callable[..., Any], n: int) -> Callable[[int, np.ndarray, np.ndarray], np.ndarray]:
    def rows(k: int, t: np.ndarray, x: np.ndarray) -> np.ndarray:
        out = np.empty((x.shape[0], n))
        for b in range(x.shape[0]):
            out[b] = _one("jump", fn(int(k), float(t[b]), x[b]), n)
        return out

    return rows


@dataclass(frozen=True)
class BatchedSystem:
    """A hybrid system with the runs on axis 0 (the reference solver's form).

    ``flow(t, x) -> dx`` with ``t`` of shape ``(B,)`` and ``x``, ``dx`` of shape
    ``(B, n)``; ``guard(t, x) -> g`` of shape ``(B, n_rules)``; ``jump(k, t, x) -> x+``
    applies rule ``k`` to the rows given. Other fields as :class:`HybridSystem`.
    """

    n: int
    n_rules: int
    flow: FlowFn
    guard: GuardFn
    jump: JumpFn
    rule_names: tuple[str, ...] = ()
    n_flow: int | None = None
    log_columns: tuple[int, ...] = ()

    def __post_init__(self) -> None:
        check_sizes(self.n, self.n_rules, self.n_flow)
        v.function("flow", self.flow)
        v.function("guard", self.guard)
        v.function("jump", self.jump)
        object.__setattr__(self, "rule_names", _names(self.n_rules, tuple(self.rule_names)))
        object.__setattr__(self, "log_columns", check_log_columns(self.log_columns, self.n))
