"""Result of :func:`~etobs.estimation.simulate`: the hybrid solution read in the paper's terms."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from etobs.errors import InputError
from etobs.estimation.problem import EstimationProblem
from etobs.hybrid.solution import HybridSolution, JumpLog


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
        holds them, and network-induced error ``e = ybar - ytilde`` (eq. (46)). In the
        observer-copy variant (``hold="innovation"``) ``ybar`` holds
        ``ytilde - yhat`` as sent and ``e = ybar - (ytilde - yhat)``.
    eta : ndarray
        ``eta_i`` of each node (first entry of its rule state; NaN for stateless rules),
        output nodes then input nodes.

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


@dataclass(frozen=True)
class EstimationResult:
    """Per-run status, transmission log and trajectories of a simulation.

    Nodes are indexed from 0 (node 0 is the paper's sensor 1).
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
        (section 6.3). With a network this counts packets *sent*, received or not.
        """
        log = self.solution.jumps
        if self.problem.network is None:
            return log
        C = self.problem.n_channels  # with a network, rules 0..C-1 are the deliveries
        keep = log.rule >= C
        return JumpLog(log.run[keep], log.rule[keep] - C, log.t[keep], log.j[keep])

    @property
    def deliveries(self) -> JumpLog:
        """Packets reaching the observer after a delay: ``(run, rule=node, t, j)`` rows.

        Empty without a network. A packet of a zero-delay link is applied within its
        transmission's jump and has no row here; a stale packet (older than the last
        one applied) has a row but was not applied (see :meth:`network_stats`).
        """
        log = self.solution.jumps
        keep = (log.rule < self.problem.n_channels) & (self.problem.network is not None)
        return JumpLog(log.run[keep], log.rule[keep], log.t[keep], log.j[keep])

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
        from etobs.estimation._network_jumps import EMPTY, LOST, N_APPLIED, OVERFLOW, STALE
        from etobs.estimation.assembly import slot_columns

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

    def status_labels(self) -> list[str]:
        """Status of each run (``"completed"``, ``"max_jumps"``, ...)."""
        return self.solution.status_labels()

    def messages(self) -> list[str]:
        """How each run ended, with the fix for failures."""
        return self.solution.messages()

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
        return self._trajectory(a.t, a.j, a.x)

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
        return self._trajectory(t, g.j, g.x)

    def _trajectory(self, t: np.ndarray, j: np.ndarray, q: np.ndarray) -> Trajectory:
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
        for i, sl in enumerate(lay.rule):
            if sl.stop > sl.start:
                eta[:, i] = flat[:, sl.start]
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
