"""Result of :func:`~etobs.estimation.simulate`: the hybrid solution read in the paper's terms."""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from etobs.errors import InputError
from etobs.estimation._network_jumps import EMPTY, LOST, N_APPLIED, OVERFLOW, STALE
from etobs.estimation.layout import slot_columns
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.solution import HybridSolution, JumpLog
from etobs.hybrid.status import Status

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr


#: What a failed run's message adds in the estimation layer's terms (the generic solver's
#: messages speak of guards and jumps; here a jump is a transmission).
STATUS_ADVICE = {
    Status.MAX_JUMPS: (
        "The jumps are transmissions: many transmissions (a short period, a tiny eps, or a "
        "state that grows without bound) end a run so; a sampled node's samples are jumps too "
        "(one per period: a long run at a short period needs a larger max_jumps)"
    ),
    Status.ZENO: (
        "The jumps are transmissions: check that every eps is > 0 and not tiny next to "
        "gamma(|e|) (Theorem 4's minimum inter-event time is gamma_i^-1(eps_i) / E) and that no "
        "rule stays in its jump set after its own transmission"
    ),
}


@dataclass(frozen=True)
class Trajectory:
    """States of the estimator at a set of hybrid times.

    For one run's arc the arrays have a leading axis of length ``K`` (points); on a save
    grid they have two leading axes ``(B, G)`` (runs, grid points).

    Attributes
    ----------
    t, j : ndarray
        Hybrid times.
    x, z, xhat, ybar, e : ndarray
        Plant state, observer state, estimate ``psi(z)``, held outputs as the observer
        holds them, and network-induced error ``e = ybar - ytilde`` (eq. (49)). In the
        observer-copy variant (``hold="innovation"``) ``ybar`` holds
        ``ytilde - yhat`` as sent and ``e = ybar - (ytilde - yhat)``.
    eta : ndarray
        ``eta_i`` of each node (first entry of its rule state; NaN for stateless rules),
        output nodes then input nodes.

    Examples
    --------
    >>> from etobs import simulate
    >>> from etobs.examples import robot_arm
    >>> arc = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 1.0).arc(0)  # every step and jump
    >>> float(arc.t[0]), arc.x.shape[1], arc.eta[0].tolist()
    (0.0, 4, [10.0, 10.0])

    """

    t: np.ndarray
    j: np.ndarray
    x: np.ndarray
    z: np.ndarray
    xhat: np.ndarray
    ybar: np.ndarray
    e: np.ndarray
    eta: np.ndarray

    @property
    def error(self) -> np.ndarray:
        """Estimation error norm ``|x - xhat|``."""
        return np.linalg.norm(self.x - self.xhat, axis=-1)

    def __repr__(self) -> str:
        from etobs.estimation.tables import trajectory_repr

        return trajectory_repr(self)

    def _repr_html_(self) -> str:
        from etobs.estimation.tables import trajectory_html

        return trajectory_html(self)


@dataclass(frozen=True)
class EstimationResult:
    """Per-run status, transmission log and trajectories of a simulation.

    Nodes are indexed from 0 (node 0 is the paper's sensor 1). :func:`etobs.simulate`
    returns it; read it with ``transmissions``, :meth:`arc` (a run's hybrid arc),
    :meth:`on_grid` (every run on the save grid), :meth:`to_pandas` and the metrics of
    :mod:`etobs.estimation`.

    Parameters
    ----------
    problem : EstimationProblem
        What was simulated.
    solution : HybridSolution
        The solver's result (status, jump log, arcs or grid of every run; its
        ``backend``, ``"engine"`` or ``"scipy"``).
    backend_reason : str
        Why that backend ran (``simulate(backend="auto")`` says it).
    notes : tuple of str
        What was done otherwise than asked, and why.

    Examples
    --------
    >>> import numpy as np
    >>> from etobs import SaveAt, simulate
    >>> from etobs.examples import robot_arm
    >>> grid = SaveAt(grid=np.linspace(0.0, 5.0, 501))
    >>> res = simulate(robot_arm(), [3.0, 2.0, 3.0, -2.0], 5.0, save=grid)
    >>> res.ok, res.n_runs, res.n_nodes, res.transmission_times(0, 0).round(3)[:3].tolist()
    (True, 1, 2, [2.347, 2.92, 3.306])
    >>> res.on_grid().xhat.shape  # (runs, grid points, n_x)
    (1, 501, 4)

    """

    problem: EstimationProblem
    solution: HybridSolution
    backend_reason: str = ""
    notes: tuple[str, ...] = ()  # what was done otherwise than asked, and why

    @property
    def backend(self) -> str:
        """The solver that ran: ``"engine"`` or ``"scipy"`` (why: ``backend_reason``)."""
        return self.solution.backend

    @property
    def n_runs(self) -> int:
        """Number of runs ``B``."""
        return self.solution.n_runs

    @property
    def n_nodes(self) -> int:
        """Number of sensor nodes ``N``."""
        return self.problem.n_nodes

    @property
    def ok(self) -> bool:
        """Whether every run completed."""
        return self.solution.ok

    @property
    def transmissions(self) -> JumpLog:
        """Every transmission: ``(run, rule=node, t, j)`` rows sorted by run then ``j``.

        ``rule`` is the node: ``0 .. N-1`` the output nodes, then the input nodes
        (section 7.3). With a network this counts packets *sent*, received or not. The
        samples of a :class:`~etobs.model.Sampled` node are jumps, not transmissions: not here.
        ``x`` holds, just after each jump, what every node has last sent (columns
        ``names``: ``sent_y<k>``, ``sent_u<k>``, node after node); the row's own node's
        columns are the value it sent, which ``to_pandas("transmissions")`` tabulates.
        """
        log = self._named_log()
        C = self.problem.n_channels
        off = C if self.problem.network is not None else 0  # with a network, rules 0..C-1 deliver
        if off == 0 and not self.problem.sampled_channels:
            return log
        keep = (log.rule >= off) & (log.rule < off + C)  # the sampled nodes' samples follow
        return replace(log[keep], rule=log.rule[keep] - off)

    @property
    def deliveries(self) -> JumpLog:
        """Packets reaching the observer after a delay: ``(run, rule=node, t, j)`` rows.

        Empty without a network. A packet of a zero-delay link is applied within its
        transmission's jump and has no row here; a stale packet (older than the last
        one applied) has a row but was not applied (see :meth:`network_stats`).
        """
        log = self._named_log()
        return log[(log.rule < self.problem.n_channels) & (self.problem.network is not None)]

    def _named_log(self) -> JumpLog:
        """The solver's jump log, its logged columns named as what they hold (the values sent)."""
        log = self.solution.jumps
        names = self.problem.layout.sent_names
        return replace(log, names=names) if log.names != names else log

    def network_stats(self) -> dict[str, np.ndarray]:
        """Fate of every node's packets over the whole run, arrays of shape ``(B, C)``.

        Keys: ``sent``; ``lost`` (by the loss process); ``overflow`` (dropped at a full
        link); ``stale`` (arrived after a newer packet, dropped); ``in_flight`` (not
        arrived by the end of the run); ``applied`` (used by the observer). The counts add
        up: ``sent = lost + overflow + stale + in_flight + applied``; each is counted
        apart (``applied`` counts the packets the observer used).
        """
        pb = self.problem
        if pb.network is None:
            raise InputError("this problem has no network: give EstimationProblem(network=Network(...))")
        q = self.solution.x_final
        C = pb.n_channels
        keys = ("lost", "overflow", "stale", "in_flight", "applied")
        out = {k: np.zeros((self.n_runs, C), dtype=np.int64) for k in keys}
        sent = self.transmissions.counts(self.n_runs, C)
        for c, ch in enumerate(pb.layout.channels):
            assert ch.net is not None
            meta = ch.net.start
            out["lost"][:, c] = q[:, meta + LOST]
            out["overflow"][:, c] = q[:, meta + OVERFLOW]
            out["stale"][:, c] = q[:, meta + STALE]
            out["applied"][:, c] = q[:, meta + N_APPLIED]
            out["in_flight"][:, c] = np.sum(q[:, slot_columns(ch)[0]] < EMPTY, axis=1)
        return {"sent": sent, **out}

    def __repr__(self) -> str:
        from etobs.estimation.tables import result_repr

        return result_repr(self)

    def _repr_html_(self) -> str:
        from etobs.estimation.tables import result_html

        return result_html(self)

    def to_pandas(self, table: str = "summary", *, window: Any = None, variables: Any = None) -> pd.DataFrame:
        """The result as a pandas table: ``"summary"``, ``"transmissions"`` or ``"grid"``.

        Nodes are numbered from 0 (node 0 is the paper's sensor 1): ``0 .. N-1`` the
        output nodes, then the input nodes of section 7.3. Each frame's ``attrs`` holds
        the window, the node names and what the columns rest on.

        Parameters
        ----------
        table : {"summary", "transmissions", "grid"}
            ``"summary"`` (default): one row per run. Columns ``run``, ``status``
            (categorical: ``completed``, ``zeno``, ...), ``message`` (how it ended, and
            the fix), ``backend``, ``t_final``, ``j_final``, ``n_steps``;
            ``transmissions_node<i>`` (node ``i``'s transmissions in ``window``, as
            :func:`~etobs.estimation.transmission_counts` with ``nodes="all"``);
            ``min_inter_event_time_node<i>`` (over the whole run, NaN below two
            transmissions, as :func:`~etobs.estimation.min_inter_event_time`); with a
            network ``lost_node<i>``, ``overflow_node<i>``, ``stale_node<i>``, ``in_flight_node<i>``,
            ``applied_node<i>`` (as :meth:`network_stats`); ``final_error``
            (``|x - xhat|`` where the run stopped); and, when a grid was kept,
            ``max_error`` (``max |x - xhat|`` over the grid points in ``window``, as
            :func:`~etobs.estimation.max_estimation_error`; ``attrs["max_error_grid"]``
            names the grid). Without a grid there is no ``max_error`` column.

            ``"transmissions"``: one row per transmission in ``window`` (with a network,
            per packet sent, received or not), sorted by run then ``j``. Columns ``run``,
            ``node``, ``node_name``, ``kind`` (``output`` or ``input``), ``t``, ``j``
            (the jump goes from ``(t, j)`` to ``(t, j + 1)``), then the value sent:
            ``sent_y<k>`` for output ``k`` (``ytilde_k(t)``, eq. (5); with
            ``hold="innovation"`` what was sent, ``ytilde_k - yhat_k``, Remark 3) and
            ``sent_u<k>`` for input ``k`` of an input node (``u_k(t)``); NaN in the
            columns of other nodes' components. The row count per run and node equals
            :func:`~etobs.estimation.transmission_counts`. ``attrs["quantities"]`` names
            each value column with the model's name and unit (``"motor angle [rad]"``).

            ``"grid"``: the saved grid in long form, one row per run, grid point,
            variable and component: columns ``run``, ``t``, ``j``, ``variable``
            (categorical: ``x``, ``z``, ``xhat``, ``ybar``, ``e``, ``eta``, ``error``),
            ``component`` (index into the variable; for ``eta`` the node; 0 for
            ``error = |x - xhat|``), ``value``, ``name`` and ``unit`` (categorical: the
            model's name and unit of the component, else its symbol ``x_1`` and ``""``;
            the node's name for ``eta``). Long rather than one column per
            component: the variables have different sizes, and a long frame filters,
            groups and plots (``seaborn``, ``df.pivot``) without knowing them. Points
            after a run stopped hold NaN with ``j = -1``. :meth:`to_xarray` holds the
            same values as arrays.
        window : (float, float), optional
            Closed time window: the rows of ``"transmissions"`` and ``"grid"``, the
            counts and ``max_error`` of ``"summary"`` (default: the whole horizon).
        variables : str or sequence of str, optional
            The grid table's variables (default: all).

        Returns
        -------
        pandas.DataFrame

        Raises
        ------
        InputError
            For an unknown table or variable, or a grid table from a result that kept
            no grid.

        Examples
        --------
        >>> from etobs import simulate
        >>> from etobs.examples import robot_arm
        >>> res = simulate(robot_arm(), [3, 2, 3, -2], 5.0)
        >>> res.to_pandas("transmissions").columns.tolist()
        ['run', 'node', 'node_name', 'kind', 't', 'j', 'sent_y0', 'sent_y1']
        >>> res.to_pandas("summary").loc[0, "status"]
        'completed'

        """
        from etobs.estimation.tables import to_pandas

        return to_pandas(self, table, window, variables)

    def to_xarray(self) -> xr.Dataset:
        """The grid values as an ``xarray.Dataset`` (needs ``SaveAt(grid=...)``).

        Variables ``x``, ``xhat`` (dims ``run, time, state``), ``z`` (``run, time,
        observer_state``), ``ybar``, ``e`` (``run, time, output``), ``eta`` (``run, time,
        node``: output nodes, then input nodes; node 0 is the paper's sensor 1),
        ``error = |x - xhat|`` and ``j`` (``run, time``). Coordinates: ``run``, ``time``
        (the save grid), the component indices, the model's names and units
        (``state_name``, ``state_unit`` on ``state``; ``observer_state_name``,
        ``observer_state_unit``; ``output_name``, ``output_unit``: symbols such as ``x_1``
        and ``""`` where the model gives none), ``node_name`` and ``node_kind`` on
        ``node``, ``status`` and ``message`` on ``run``. Attributes: ``backend``,
        ``backend_reason``, ``t_span``, ``hold``. Points after a run stopped hold NaN
        with ``j = -1``.

        Raises
        ------
        InputError
            When the result kept no grid, or only ``max |x - xhat|`` over it.

        """
        from etobs.estimation.tables import to_xarray

        return to_xarray(self)

    def status_labels(self) -> list[str]:
        """Status of each run (``"completed"``, ``"max_jumps"``, ...)."""
        return self.solution.status_labels()

    def messages(self) -> list[str]:
        """How each run ended, with the fix for failures."""
        sol = self.solution
        # a blow-up ends `nonfinite`, or `step_underflow` when the state is still finite
        blown = np.flatnonzero(np.isin(sol.status, (Status.NONFINITE, Status.STEP_UNDERFLOW)))
        if blown.size:
            details = list(sol.failures or ("",) * sol.n_runs)
            for b in blown:
                details[b] = "; ".join(d for d in (details[b], self._blown_up(int(b))) if d)
            sol = replace(sol, failures=tuple(details))
        return sol.messages(STATUS_ADVICE)

    def _blown_up(self, run: int) -> str:
        """Which of the plant and the observer blew up in ``run``, from its last state."""
        lay, q = self.problem.layout, self.solution.x_final[run]
        parts = {"the plant's state x": q[lay.x], "the observer's state z": q[lay.z]}
        bad = [name for name, v in parts.items() if not np.all(np.isfinite(v))]
        if bad:
            return f"{' and '.join(bad)} {'is' if len(bad) == 1 else 'are'} not finite"
        mx, mz = (float(np.max(np.abs(v), initial=0.0)) for v in parts.values())
        larger = "the plant's state x" if mx >= mz else "the observer's state z"
        return f"{larger} is the larger at the last state reached (max |x| = {mx:.3g}, max |z| = {mz:.3g})"

    def transmission_times(self, run: int, node: int) -> np.ndarray:
        """Transmission times of ``node`` in ``run``."""
        return self.transmissions.times(run, node)

    def arc(self, run: int) -> Trajectory:
        """The full hybrid arc of ``run`` (requires ``SaveAt(steps=True)``)."""
        arcs = self.solution.arcs
        if arcs is None:
            raise InputError("this result kept no arcs: simulate with save=SaveAt(steps=True)")
        if not 0 <= run < self.n_runs:
            raise InputError(f"`run` must be in 0..{self.n_runs - 1}; got {run}")
        a = arcs[run]
        return self.trajectory(a.t, a.j, a.x)

    def samples(self, run: int, node: int) -> tuple[np.ndarray, np.ndarray]:
        """The samples sampled node ``node`` read in ``run``: times ``t_k`` and ``ytilde_i(t_k)``.

        What a deployed node (:mod:`etobs.runtime.sensor`, the generated C module) fed these
        values decides as the simulation did: the same samples send, bit for bit when
        ``ytilde_i`` is computed alike (``h`` picks states, no noise ``m``). Read from the
        arc at each of the node's samples (requires ``SaveAt(steps=True)``), with the
        problem's ``h`` and ``m`` in numpy. (A node of the observer-copy hold sends
        ``ytilde_i - yhat_i``, which a deployed node does not: the runtime refuses that hold.)

        Returns
        -------
        t : ndarray, shape (K,)
        y : ndarray, shape (K, n_y_i)

        """
        pb = self.problem
        sampled = [c for c in pb.sampled_channels if c < pb.n_nodes]
        if isinstance(node, bool) or not isinstance(node, int | np.integer) or node not in sampled:
            raise InputError(f"`node` must be a sampled output node, one of {sampled}; got {node!r}")
        if isinstance(run, bool) or not isinstance(run, int | np.integer):
            raise InputError(f"`run` must be an integer in 0..{self.n_runs - 1}; got {run!r}")
        a = self.arc(run)  # checks run's range and the arcs
        arcs = self.solution.arcs
        assert arcs is not None
        log = self.solution.jumps
        rule = pb.sample_rule(int(node))
        rows = (log.run == run) & (log.rule == rule)
        after = np.searchsorted(arcs[run].j, log.j[rows] + 1, side="left")  # the state after the sample
        t = a.t[after]
        y = pb.ytilde(t, a.x[after])[:, list(pb.nodes[node].outputs)]
        return t, y

    def on_grid(self) -> Trajectory:
        """States of every run on the save grid, arrays of shape ``(B, G, ...)``."""
        g = self.solution.grid
        if g is None and self.solution.grid_max is not None:
            raise InputError(
                "this result kept only max |x - xhat| over its grid (SaveAt(max_distance=...)): "
                "simulate with SaveAt(grid=...) and no max_distance to keep the states"
            )
        if g is None:
            raise InputError("this result kept no grid: simulate with save=SaveAt(grid=...)")
        t = np.broadcast_to(g.t, g.j.shape)
        return self.trajectory(t, g.j, g.x)

    def trajectory(self, t: np.ndarray, j: np.ndarray, q: np.ndarray) -> Trajectory:
        """Read solver states ``q`` at hybrid times ``(t, j)`` in the paper's terms.

        ``q`` has the solver's state on its last axis (as in ``solution.arcs`` or
        ``solution.grid``); :meth:`arc` and :meth:`on_grid` are this for what was kept.
        The one place ``x, z, xhat, ybar, e, eta`` are derived from the solver's state.
        """
        pb, lay = self.problem, self.problem.layout
        flat = q.reshape(-1, q.shape[-1])
        tf = np.asarray(t, dtype=float).reshape(-1)
        x, z, ybar = flat[:, lay.x], flat[:, lay.z], flat[:, lay.ybar]
        with np.errstate(invalid="ignore"):
            e = ybar - pb.ytilde(tf, x)
            xhat = pb.psi(z)
            if pb.hold == "innovation":  # ybar holds ytilde - yhat as sent (Remark 3)
                e = e + pb.calls().h(xhat)
        eta = np.full((flat.shape[0], pb.n_channels), np.nan)
        for i, ch in enumerate(lay.channels):
            if ch.rule.n_own:
                eta[:, i] = flat[:, ch.rule_state.start]
        lead = q.shape[:-1]

        def shape(a: np.ndarray) -> np.ndarray:
            return a.reshape(*lead, a.shape[-1])

        return Trajectory(
            t=np.asarray(t),
            j=np.asarray(j),
            x=shape(x),
            z=shape(z),
            xhat=shape(xhat),
            ybar=shape(ybar),
            e=shape(e),
            eta=shape(eta),
        )
