"""The event-triggered estimation problem and its hybrid model, eq. (16)--(22).

Its hybrid state ``q`` is laid out in :mod:`etobs.estimation.layout` (held outputs
``ybar`` rather than the paper's ``e``, eq. (4)); :meth:`EstimationProblem.hybrid_system`
assembles the model (:mod:`etobs.estimation.assembly`).
"""

from __future__ import annotations

import warnings
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs.errors import InputError, InputTypeError, ModelError
from etobs.estimation._network_jumps import EMPTY
from etobs.estimation.assembly import build_system
from etobs.estimation.calls import ModelCalls, refuse_complex
from etobs.estimation.layout import StateLayout, slot_columns, state_layout
from etobs.hybrid.system import BatchedSystem, raised, read_only
from etobs.model.network import Network
from etobs.model.node import InputNode, Node
from etobs.model.observer import Observer
from etobs.model.plant import Plant
from etobs.model.quantities import Quantity
from etobs.model.sampled import Sampled
from etobs.model.signals import Signal, Sinusoid, as_signal


@dataclass(frozen=True)
class EstimationProblem:
    """Plant, observer, sensor nodes and signals of one event-triggered estimator.

    Parameters
    ----------
    plant : Plant
    observer : Observer
    nodes : sequence of Node
        Their output sets must partition ``0 .. n_y - 1``.
    u : Signal, callable, array_like or None
        Known input ``u(t)`` (dimension ``n_u``); ``None`` is zero.
    v : Signal, callable, array_like or None
        Unknown disturbance ``v(t)`` (dimension ``n_v``).
    m : Signal, callable, array_like or None
        Measurement noise ``m(t)`` (dimension ``n_y``), eq. (46): ``ytilde = h(x) + m``.
    input_nodes : sequence of InputNode, optional
        Section 7.3: nodes that send components of ``u`` to the observer by their own
        rules; the observer runs on the held ``ubar`` for those components. Their sets
        must be disjoint.
    hold : {"output", "innovation"}
        ``"output"`` (the paper): the observer holds the outputs sent. ``"innovation"``:
        the observer-copy variant of Remark 3, where node ``i`` runs a copy of the
        observer and sends the output estimation error ``ytilde_i - yhat_i``; the
        observer holds it and its rule acts on ``(ybar_i - yhat_i)_sent - (ytilde_i -
        yhat_i)``. Simulated with a perfect copy (the observer's own ``yhat``).
    network : Network, optional
        Delays and losses between the nodes and the observer (not in the paper; see
        :mod:`etobs.model.network`). Default: the paper's ideal network.

    Examples
    --------
    A damped oscillator measured by two nodes, one output each:

    >>> import numpy as np
    >>> from etobs import DynamicRule, EstimationProblem, Linear, Node, Plant, Quadratic, luenberger
    >>> A = np.array([[0.0, 1.0], [-2.0, -0.5]])
    >>> plant = Plant(f_p=lambda t, x, u, v: A @ x, h=lambda x: x, n_x=2, n_y=2)
    >>> observer = luenberger(lambda t, x, u: A @ x, L=np.eye(2) * 3.0)
    >>> rule = DynamicRule(gamma=Quadratic(1.0), alpha=Linear(1.0), sigma=0.5, c=0.5, eps=1e-3)
    >>> problem = EstimationProblem(plant, observer, nodes=[Node([0], rule), Node([1], rule)])
    >>> problem.n_nodes, problem.rule_names
    (2, ('node0', 'node1'))

    """

    plant: Plant
    observer: Observer
    nodes: tuple[Node, ...]
    u: Any = None
    v: Any = None
    m: Any = None
    input_nodes: tuple[InputNode, ...] = ()
    hold: str = "output"
    network: Network | None = None
    layout: StateLayout = field(init=False, repr=False)
    _calls: dict[bool, Any] = field(init=False, repr=False, compare=False, default_factory=dict)

    def __post_init__(self) -> None:
        if not isinstance(self.plant, Plant):
            raise InputTypeError(f"`plant` must be a Plant; got {type(self.plant).__name__}")
        if not isinstance(self.observer, Observer):
            raise InputTypeError(f"`observer` must be an Observer; got {type(self.observer).__name__}")
        if isinstance(self.nodes, Node) or not isinstance(self.nodes, tuple | list):
            raise InputTypeError(
                "`nodes` must be a list or tuple of Node objects (one Node is nodes=[Node(...)]); "
                f"got {type(self.nodes).__name__}"
            )
        nodes = tuple(self.nodes)
        if not nodes or not all(isinstance(nd, Node) for nd in nodes):
            got = [type(nd).__name__ for nd in nodes]
            raise InputTypeError(f"`nodes` must be a non-empty sequence of Node objects; got {got}")
        object.__setattr__(self, "nodes", nodes)
        p = self.plant
        _check_observer_size(self.observer, p)
        _check_partition(nodes, p.n_y)
        if isinstance(self.input_nodes, InputNode) or not isinstance(self.input_nodes, tuple | list):
            raise InputTypeError(
                "`input_nodes` must be a list or tuple of InputNode objects; "
                f"got {type(self.input_nodes).__name__}"
            )
        inputs = tuple(self.input_nodes)
        if not all(isinstance(nd, InputNode) for nd in inputs):
            raise InputTypeError("`input_nodes` must be a sequence of InputNode objects")
        object.__setattr__(self, "input_nodes", inputs)
        _check_inputs(inputs, p.n_u)
        if self.hold not in ("output", "innovation"):
            raise InputError(f"`hold` must be 'output' or 'innovation'; got {self.hold!r}")
        if self.network is not None and not isinstance(self.network, Network):
            raise InputTypeError(f"`network` must be a Network or None; got {type(self.network).__name__}")
        if self.network is not None and self.hold == "innovation":
            raise InputError(
                "`hold='innovation'` (Remark 3) assumes every node's observer copy equals the observer; "
                "with a lossy or delayed `network` the copies would diverge, which is not simulated: "
                "use hold='output' with a network"
            )
        object.__setattr__(self, "u", as_signal("u", self.u, p.n_u, "n_u"))
        object.__setattr__(self, "v", as_signal("v", self.v, p.n_v, "n_v"))
        object.__setattr__(self, "m", as_signal("m", self.m, p.n_y, "n_y"))
        object.__setattr__(self, "layout", state_layout(p, self.observer, nodes, inputs, self.network))
        _check_shapes(self)
        _check_noise(self)
        _check_sigma_c(self)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_calls"] = {}  # compiled functions stay in their process
        return state

    def __setstate__(self, state: dict[str, Any]) -> None:
        self.__dict__.update(state)

    @property
    def n_nodes(self) -> int:
        """Number of sensor nodes ``N``."""
        return len(self.nodes)

    @property
    def n_channels(self) -> int:
        """Number of nodes of every kind: ``N`` output nodes, then the input nodes."""
        return len(self.nodes) + len(self.input_nodes)

    @property
    def channel_names(self) -> tuple[str, ...]:
        """Names of the output nodes, then the input nodes."""
        return tuple(ch.name for ch in self.layout.channels)

    def quantities(self, variable: str) -> tuple[Quantity, ...]:
        """The entries of a result variable, with the names and units the model gives them.

        Parameters
        ----------
        variable : {"x", "xhat", "z", "y", "ybar", "e", "u"}
            ``x`` and ``xhat``: the plant's states; ``z``: the observer's; ``y``,
            ``ybar`` and ``e``: the plant's outputs; ``u``: its known inputs.

        Returns
        -------
        tuple of Quantity
            One per entry, in order (:class:`~etobs.model.quantities.Quantity`).

        """
        if variable == "z":
            return self.observer.quantities()
        vector = {"x": "x", "xhat": "x", "y": "y", "ybar": "y", "e": "y", "u": "u"}.get(variable)
        if vector is None:
            raise InputError(f"`variable` must be one of x, xhat, z, y, ybar, e, u; got {variable!r}")
        return self.plant.quantities(vector)

    @property
    def rule_names(self) -> tuple[str, ...]:
        """Names of the hybrid model's jump rules.

        The nodes' transmissions; with a network, after one delivery rule per node
        (``"deliver <node>"``); then the samples of the sampled nodes
        (``"sample <node>"``, :class:`~etobs.model.Sampled`), in node order.
        """
        names = self.channel_names
        if self.network is not None:
            names = tuple(f"deliver {n}" for n in names) + names
        return names + tuple(f"sample {self.channel_names[c]}" for c in self.sampled_channels)

    @property
    def sampled_channels(self) -> tuple[int, ...]:
        """The channels whose rule is :class:`~etobs.model.Sampled`, in order: sample rule ``m`` is theirs."""
        return tuple(c for c, ch in enumerate(self.layout.channels) if isinstance(ch.rule, Sampled))

    @property
    def first_sample_rule(self) -> int:
        """The jump rule of the first sampled channel's samples: after the deliveries and transmissions."""
        return self.n_channels * (2 if self.network is not None else 1)

    def sample_rule(self, channel: int) -> int:
        """The jump rule of sampled channel ``channel``'s samples (:attr:`rule_names`)."""
        return self.first_sample_rule + self.sampled_channels.index(channel)

    @property
    def extended(self) -> bool:
        """Whether the problem goes beyond the base setting (input nodes, copy hold, a network)."""
        return bool(self.input_nodes) or self.hold != "output" or self.network is not None

    def calls(self, compiled: bool | None = None) -> ModelCalls:
        """The model functions on batches of runs (:class:`~etobs.estimation.calls.ModelCalls`).

        ``compiled=None`` compiles them when numba can and calls the Python functions
        otherwise (for evaluating results); ``False`` always calls the Python functions.
        """
        key = compiled is not False
        if key not in self._calls:
            if compiled is None:
                try:
                    self._calls[True] = ModelCalls(self, compiled=True)
                except ModelError:
                    self._calls[True] = self.calls(False)
            else:
                self._calls[key] = ModelCalls(self, compiled=key)
        return self._calls[key]

    def psi(self, z: np.ndarray) -> np.ndarray:
        """State estimate ``xhat = psi(z)`` of a batch, shape ``(..., n_z)`` to ``(..., n_x)``."""
        if self.observer.psi is None:
            return z[..., : self.plant.n_x]
        flat = z.reshape(-1, z.shape[-1])
        return self.calls().psi(flat).reshape(*z.shape[:-1], self.plant.n_x)

    def ytilde(self, t: np.ndarray, x: np.ndarray, compiled: bool | None = None) -> np.ndarray:
        """Measured output ``ytilde = h(x) + m(t)`` (eq. (46)) of a batch; ``compiled`` as in ``calls``."""
        m: Signal = self.m
        return self.calls(compiled).h(x) + m(t)

    def initial_state(
        self, x0: np.ndarray, z0: np.ndarray, e0: np.ndarray, t0: float, run_ids: np.ndarray | None = None
    ) -> np.ndarray:
        """Hybrid state at ``t0``: ``ybar = ytilde(t0) + e0`` and each rule's own start.

        The held inputs start exact, ``ubar(t0) = u(t0)``; the observer-copy variant
        holds ``ytilde(t0) - yhat(t0) + e0``. With a network the nodes' sent values
        equal the held ones, no packet is in flight, and run ``b`` of the batch draws its
        packets' fates from the stream ``(seed, run_ids[b], node)`` (default
        ``run_ids = 0 .. B-1``).
        """
        b = x0.shape[0]
        lay = self.layout
        tt = np.full(b, t0)
        q = np.zeros((b, lay.n))
        q[:, lay.x] = x0
        q[:, lay.z] = z0
        # the Python functions: one call per run, and compiling them on their own here
        # would cost a new model more than a second (the engine compiles its own model)
        ybar = self.ytilde(tt, x0, compiled=False) + e0
        _finite_at_start(ybar, "`h` (or the noise `m`) returned a value that is not finite at `x0`")
        if self.hold == "innovation":
            ybar = ybar - self.calls(False).h(self.psi(z0))
            _finite_at_start(ybar, "`h(psi(z0))` is not finite (the observer-copy hold starts from it)")
        q[:, lay.ybar] = ybar
        u0 = self.u(tt)
        for ch in lay.channels:
            if ch.kind == "u":
                q[:, ch.held] = u0[:, ch.index]
            q[:, ch.rule_state] = ch.rule.initial_state()
            if isinstance(ch.rule, Sampled):  # its first sample is the first not before t0
                q[:, ch.rule_state.start + ch.rule.n_own] = ch.rule.first_sample(t0)
            q[:, ch.sent] = q[:, ch.held]
            if ch.net is not None:
                q[:, slot_columns(ch)[0]] = EMPTY
        if lay.run is not None:
            q[:, lay.run] = np.arange(b) if run_ids is None else run_ids
        return q

    def hybrid_system(self) -> BatchedSystem:
        """The hybrid model (16)--(22) as a :class:`~etobs.hybrid.BatchedSystem` (the reference's).

        Jump rules ``0 .. C-1`` are the nodes' transmissions (output nodes, then input
        nodes); with a network, rules ``0 .. C-1`` deliver their packets and ``C .. 2C-1``
        are the transmissions. It calls the user's Python functions as they are.
        """
        return build_system(self, self.calls(False))


def _check_observer_size(obs: Observer, plant: Plant) -> None:
    """Refuse an observer smaller than the plant, or whose gain ``L`` has another number of outputs.

    The first place ``n_y`` and the observer meet: ``L`` (``gain_shape``) must be
    ``(n_x, n_y)``; a transposed ``L`` shows as an ``n_z`` below ``n_x``, so the message
    names ``L`` then.
    """
    expected = f"expected (n_x, n_y) = ({plant.n_x}, {plant.n_y}) for this plant"
    gain = obs.gain_shape
    if gain is not None and (gain[0] != plant.n_x or gain[1] != plant.n_y):
        hint = ": is L transposed?" if gain == (plant.n_y, plant.n_x) else ""
        raise InputError(
            f"the observer's gain `L` has shape {gain}; {expected} (one row per state, one column "
            f"per output){hint}"
        )
    if obs.n_z < plant.n_x:
        raise InputError(f"observer `n_z` = {obs.n_z} is smaller than the plant's n_x = {plant.n_x}")


def _check_partition(nodes: tuple[Node, ...], n_y: int) -> None:
    owner: dict[int, list[int]] = {}
    for i, nd in enumerate(nodes):
        for k in nd.outputs:
            owner.setdefault(k, []).append(i)
    outside = sorted(k for k in owner if k >= n_y)
    twice = {k: o for k, o in owner.items() if len(o) > 1}
    missing = [k for k in range(n_y) if k not in owner]
    problems = []
    if outside:
        problems.append(f"outputs {outside} do not exist (n_y = {n_y})")
    for k, o in sorted(twice.items()):
        problems.append(f"output {k} is claimed by nodes {o}")
    if missing:
        problems.append(f"outputs {missing} belong to no node")
    if problems:
        raise InputError(
            f"the nodes' output sets must partition the outputs 0..{n_y - 1}: " + "; ".join(problems)
        )


def _check_inputs(nodes: tuple[InputNode, ...], n_u: int) -> None:
    seen: dict[int, int] = {}
    for i, nd in enumerate(nodes):
        for k in nd.inputs:
            if k >= n_u:
                raise InputError(f"input node {i} sends input {k}, which does not exist (n_u = {n_u})")
            if k in seen:
                raise InputError(
                    f"input {k} is sent by input nodes {seen[k]} and {i}; each input by one node"
                )
            seen[k] = i


def _finite_at_start(ybar: np.ndarray, what: str) -> None:
    """Refuse held outputs that start NaN or infinite, naming the function (not ``x0``, which is finite)."""
    bad = ~np.all(np.isfinite(ybar), axis=1)
    if bad.any():
        raise ModelError(
            f"{what}, in runs {np.flatnonzero(bad).tolist()}: the held outputs `ybar` start from it; "
            "check the function near the initial state"
        )


def _check_shapes(pb: EstimationProblem) -> None:
    """Call every model function once, for one run, and check what it returns.

    The inputs are read-only, as in the solvers: a function that writes into them is
    refused here, naming it, on either backend.
    """
    p, o = pb.plant, pb.observer
    t0 = np.zeros(1)
    x, z = read_only(np.zeros(p.n_x)), read_only(np.zeros(o.n_z))
    u, v = read_only(pb.u(t0)[0]), read_only(pb.v(t0)[0])

    def call(name: str, fn: Any, *args: Any, **shown: Any) -> Any:
        # ``shown``: the call as the user wrote the function, for the message
        try:
            return fn(*args)
        except Exception as exc:  # the user's code may raise anything; say whose it is and on what
            if isinstance(exc, ValueError) and "read-only" in str(exc):
                raise ModelError(raised(name, exc)) from exc
            raise ModelError(_probe_failed(name, exc, shown)) from exc

    def check(name: str, out: Any, n: int, what: str) -> np.ndarray:
        try:
            arr = refuse_complex(name, np.asarray(out))
            arr = np.asarray(arr, dtype=float)
        except (TypeError, ValueError) as exc:
            if isinstance(exc, ModelError):
                raise
            arr = np.asarray(out, dtype=object)
        if arr.shape != (n,):
            hint = ""
            if arr.ndim == 2:
                hint = ": functions are written for one run (1-D arrays), not a batch"
            raise ModelError(
                f"`{name}` returned shape {arr.shape} for one run; expected ({n},) = ({what},){hint}"
            )
        return arr

    pp, op = {"p": p.params} if p.params.size else {}, {"p": o.params} if o.params.size else {}
    fp = call("f_p", p.call_f_p, 0.0, x, u, v, t=0.0, x=x, u=u, v=v, **pp)
    check("f_p", fp, p.n_x, "n_x")
    y = read_only(check("h", call("h", p.call_h, x, x=x, **pp), p.n_y, "n_y"))
    xhat = read_only(check("psi", call("psi", o.call_psi, z, p.n_x, z=z, **op), p.n_x, "n_x"))
    yhat = read_only(np.asarray(call("h", p.call_h, xhat, x=xhat, **pp), dtype=float))
    fo = call("f_o", o.call_f_o, 0.0, z, u, y, yhat, t=0.0, z=z, u=u, ybar=y, yhat=yhat, **op)
    check("f_o", fo, o.n_z, "n_z")


#: The dimension of each argument of the model functions, as the messages name it.
_DIMS = {"x": "n_x", "u": "n_u", "v": "n_v", "z": "n_z", "ybar": "n_y", "yhat": "n_y", "p": "params"}


def _probe_failed(name: str, exc: Exception, args: dict[str, Any]) -> str:
    """What ``_check_shapes`` says when the user's function ``name`` raised ``exc`` on ``args``."""
    parts = [f"{k}={a!r}" if k == "t" else f"{k} of shape {np.shape(a)}" for k, a in args.items()]
    text = (
        f"`{name}` raised {type(exc).__name__}: {exc}; etobs called it once at construction, to check "
        f"its output's shape, as {name}({', '.join(parts)})"
    )
    empty = [k for k, a in args.items() if k in ("u", "v") and np.size(a) == 0]
    if empty and isinstance(exc, IndexError) and "size 0" in str(exc):  # numpy's words for an empty axis
        what = " and ".join(empty) + (" are" if len(empty) > 1 else " is")
        sizes = ", ".join(f"{_DIMS[k]}=..." for k in empty)
        text += (
            f". {what} empty (the plant's {', '.join(_DIMS[k] for k in empty)} = 0): if `{name}` reads "
            f"{'one of them' if len(empty) > 1 else 'it'}, give the Plant its size ({sizes})"
        )
    return text


def _check_noise(pb: EstimationProblem) -> None:
    """Warn when a node's ``eps_i <= gamma_i(2 m_i)`` (section 7.2) for sinusoidal noise.

    The rule sees ``e~_i = e_i + m_i(t_k) - m_i(t)``; a sinusoid's offset cancels there,
    so ``m_i`` is the norm of the node's amplitudes. Without the condition the noise
    alone can trigger transmissions, and the minimum inter-event time is lost.
    """
    if not isinstance(pb.m, Sinusoid):
        return
    for i, nd in enumerate(pb.nodes):
        gamma, eps = getattr(nd.rule, "gamma", None), getattr(nd.rule, "eps", None)
        if gamma is None or eps is None:
            continue
        bound = float(np.linalg.norm(pb.m.amplitude[list(nd.outputs)]))
        g2m = float(np.asarray(gamma(np.array([2.0 * bound])))[0])
        if bound > 0 and eps <= g2m:
            warnings.warn(
                f"node {i} ({nd.name!r}): eps = {eps:g} <= gamma(2 m) = {g2m:.6g} with noise bound "
                f"m = {bound:g}: section 7.2's condition fails, so noise alone can trigger transmissions; "
                "raise eps",
                RuntimeWarning,
                stacklevel=4,  # the user's EstimationProblem(...), through __init__ and __post_init__
            )


def _check_sigma_c(pb: EstimationProblem) -> None:
    """Warn, naming the node, when ``sigma_i c_i >= 1``: no ``d_i`` satisfies Theorem 1."""
    nodes = [("node", i, nd) for i, nd in enumerate(pb.nodes)]
    nodes += [("input node", i, nd) for i, nd in enumerate(pb.input_nodes)]
    for kind, i, nd in nodes:
        sigma, c = getattr(nd.rule, "sigma", None), getattr(nd.rule, "c", None)
        if sigma is None or c is None or sigma * c < 1:
            continue
        warnings.warn(
            f"{kind} {i} ({nd.name!r}): sigma*c = {sigma:g}*{c:g} = {sigma * c:.6g} >= 1: Theorem 1 needs "
            "sigma_i c_i < 1, so the paper's guarantees do not hold; lower sigma or c",
            RuntimeWarning,
            stacklevel=4,  # the user's EstimationProblem(...), through __init__ and __post_init__
        )
