"""ISS gains of a Luenberger observer from its quadratic Lyapunov function (section 8).

With ``V(xi) = xi' P xi`` for the estimation error ``xi = x - xhat`` and
``P A_cl,k + A_cl,k' P <= -Q`` at every vertex (:mod:`etobs.design.lmi`), the error of
the observer fed with ``ybar = y + e`` obeys ``xi' = A_cl xi + E_v v - sum_i L_i e_i``
(``L_i``: the columns of ``L`` of node ``i``'s outputs; ``E_v``: how the disturbance enters
the plant, ``f_p(x, u, v) = f_p(x, u, 0) + E_v v``, the identity in the paper's case study,
section 8, where ``x' = ... + v``). Young's inequality
``2 |xi| r <= c |xi|^2 + r^2 / c`` on each cross term gives Assumption 2
(eq. (13)) with, for any ``c_v, c_1, ..., c_N > 0`` with
``lambda_min(Q) - c_v - sum_i c_i > 0``::

    alpha(s)   = (lambda_min(Q) - c_v - sum_i c_i) / lambda_max(P) * s
    theta(s)   = ||P E_v||^2 / c_v * s^2
    gamma_i(s) = ||P L_i||^2 / c_i * s^2

which are the paper's gains (section 8) for ``E_v = I``. ``theta`` bounds the effect of
``|v|``, the norm of the plant's disturbance *input*; with ``E_v = I`` in place of, say,
``30 e_4`` it would be 900 times too small.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from etobs import _validate as v
from etobs.design.hypotheses import Region
from etobs.design.lmi import ObserverGain
from etobs.errors import InputError
from etobs.model.plant import Plant


@dataclass(frozen=True)
class QuadraticISS:
    """Assumption 2 with linear ``alpha`` and quadratic ``theta``, ``gamma_i`` (eq. (13)).

    Attributes
    ----------
    a : float
        ``alpha(s) = a s``.
    k_v : float
        ``theta(s) = k_v s^2``.
    k : tuple of float
        ``gamma_i(s) = k[i] s^2``, one per node.
    lambda_min_P, lambda_max_P : float
        Extreme eigenvalues of ``P`` (``lambda_min_P |xi|^2 <= V <= lambda_max_P |xi|^2``).
    P : ndarray, shape (n_x, n_x), optional
        The Lyapunov matrix the gains rest on (``None`` for gains given by hand); its
        extreme eigenvalues must be ``lambda_min_P`` and ``lambda_max_P``.
    P_origin : str
        How ``P`` was found (:attr:`~etobs.design.ObserverGain.origin`).
    c_v, c : float and tuple of float, optional
        The split constants of :func:`quadratic_iss_gains` (``nan`` and ``()`` when not known).
    E_v : ndarray, shape (n_x, n_v), optional
        The disturbance input matrix ``theta`` was computed for (``x' = ... + E_v v``);
        ``None`` for gains given by hand, whose ``theta`` :func:`~etobs.design.certify`
        then takes on trust (with a note).
    L, Q : ndarray, optional
        The observer gain and decrease matrix the gains were computed from
        (:class:`~etobs.design.ObserverGain`); :func:`~etobs.design.certify` ties them
        to the problem's observer and plant. ``None`` for gains given by hand, which it
        then states as assumed.
    region : Region, optional
        Where the design's slope bounds hold (``None``: everywhere); stated by certificates.

    """

    a: float
    k_v: float
    k: tuple[float, ...]
    lambda_min_P: float
    lambda_max_P: float
    P: np.ndarray | None = field(default=None, compare=False)
    P_origin: str = ""
    c_v: float = math.nan
    c: tuple[float, ...] = ()
    E_v: np.ndarray | None = field(default=None, compare=False)
    L: np.ndarray | None = field(default=None, compare=False)
    Q: np.ndarray | None = field(default=None, compare=False)
    region: Region | None = None

    def __post_init__(self) -> None:
        v.real("a", self.a, lower=0.0, lower_open=True)
        v.real("k_v", self.k_v, lower=0.0)
        for i, ki in enumerate(self.k):
            v.real(f"k[{i}]", ki, lower=0.0, lower_open=True)
        v.real("lambda_min_P", self.lambda_min_P, lower=0.0, lower_open=True)
        v.real("lambda_max_P", self.lambda_max_P, lower=self.lambda_min_P)
        if self.P is not None:  # the error bound divides by lambda_min_P: it must be P's
            P = np.array(v.matrix("P", self.P, (None, None)))  # a copy, read-only: the gains rest on it
            P.setflags(write=False)
            object.__setattr__(self, "P", P)
            eig = np.linalg.eigvalsh(P)
            if not np.allclose(eig[[0, -1]], [self.lambda_min_P, self.lambda_max_P], rtol=1e-9, atol=0.0):
                raise InputError(
                    f"`P` has extreme eigenvalues ({eig[0]:.6g}, {eig[-1]:.6g}); got lambda_min_P = "
                    f"{self.lambda_min_P:.6g}, lambda_max_P = {self.lambda_max_P:.6g}"
                )
        if self.E_v is not None:  # read-only, as P: theta rests on it
            rows = None if self.P is None else self.P.shape[0]
            E_v = np.array(v.matrix("E_v", self.E_v, (rows, None)))
            E_v.setflags(write=False)
            object.__setattr__(self, "E_v", E_v)
        for name in ("L", "Q"):  # read-only, as P: the gains rest on them
            if getattr(self, name) is not None:
                arr = np.array(v.matrix(name, getattr(self, name), (None, None)))
                arr.setflags(write=False)
                object.__setattr__(self, name, arr)

    @property
    def n_nodes(self) -> int:
        """Number of nodes ``N``."""
        return len(self.k)


def quadratic_iss_gains(
    gain: ObserverGain,
    nodes: Sequence[Sequence[int]],
    *,
    c_v: float,
    c: Sequence[float],
    E_v: Any = None,
) -> QuadraticISS:
    """The ISS gains of Assumption 2 from ``P``, ``L``, ``Q`` and the split constants.

    Parameters
    ----------
    gain : ObserverGain
        ``L``, ``P`` and ``Q`` (from :func:`~etobs.design.observer_gain` or
        :func:`~etobs.design.check_gain`); it must pass its re-check.
    nodes : sequence of sequence of int
        Output indices of each node (node ``i`` uses the columns ``L[:, nodes[i]]``).
    c_v : float
        Share of ``lambda_min(Q)`` spent on the disturbance ``v`` (> 0).
    c : sequence of float
        Share spent on each node's network-induced error (> 0 each), one per node; a
        single number is refused (it could mean each node's share or their sum).
    E_v : array_like, shape (n_x, n_v), optional
        How the disturbance ``v`` enters the plant: ``x' = ... + E_v v`` (the ``E`` of
        :func:`~etobs.model.linear_plant`). Default the identity (``n_v = n_x``), as in the
        paper's case study (section 8). ``theta(s) = ||P E_v||^2 / c_v s^2`` then bounds
        the effect of ``|v|`` itself; :func:`~etobs.design.certify` refuses gains whose
        ``E_v`` does not match the plant's.

    Raises
    ------
    InputError
        When a constant is not positive, or ``lambda_min(Q) - c_v - sum(c) <= 0`` (the
        message gives both numbers), ``gain`` fails its re-check, or ``E_v`` has not
        ``n_x`` rows.

    Examples
    --------
    >>> import numpy as np
    >>> from etobs.design import check_gain
    >>> g = check_gain([[-1.0]], [[1.0]], [[1.0]])
    >>> iss = quadratic_iss_gains(g, [[0]], c_v=0.25, c=[0.25])
    >>> round(iss.a * iss.lambda_max_P, 6)  # (lambda_min(Q) - c_v - c_1)
    0.5

    """
    if not isinstance(gain, ObserverGain):
        raise InputError(f"`gain` must be an ObserverGain; got {type(gain).__name__}")
    if not gain.ok:
        raise InputError(
            f"`gain` does not pass its LMI re-check ({'; '.join(gain.notes) or 'residuals > 0'})"
        )
    v.real("c_v", c_v, lower=0.0, lower_open=True)
    if isinstance(c, int | float | np.number):  # a number is ambiguous: on each node, or the sum?
        raise InputError(
            f"`c` must be a sequence with one constant per node ({len(nodes)}); got the number {c!r}: "
            f"write c={[c] * len(nodes)!r} for {c!r} on every node"
        )
    cs = [v.real(f"c[{i}]", ci, lower=0.0, lower_open=True) for i, ci in enumerate(c)]
    if len(cs) != len(nodes):
        raise InputError(f"`c` must have one constant per node ({len(nodes)}); got {len(cs)}")
    n_y = gain.L.shape[1]
    cols = []
    for i, idx in enumerate(nodes):
        ix = list(idx)
        if not ix or any(not 0 <= j < n_y for j in ix):
            raise InputError(f"`nodes[{i}]` must list output indices in 0..{n_y - 1}; got {ix}")
        cols.append(ix)
    covered = sorted(j for ix in cols for j in ix)
    if covered != list(range(n_y)):
        raise InputError(
            f"`nodes` must share out the outputs 0..{n_y - 1} of L, each exactly once (every column of L "
            f"enters the error dynamics); got {[list(ix) for ix in cols]}"
        )
    n_x = gain.P.shape[0]
    E_v = np.eye(n_x) if E_v is None else v.matrix("E_v", E_v, (n_x, None))
    lam_q = float(np.linalg.eigvalsh(gain.Q).min())
    spare = lam_q - c_v - sum(cs)
    if spare <= 0:
        raise InputError(
            f"the split constants must leave lambda_min(Q) - c_v - sum(c) > 0; got "
            f"{lam_q:.6g} - {c_v:.6g} - {sum(cs):.6g} = {spare:.6g}"
        )
    eig_P = np.linalg.eigvalsh(gain.P)
    return QuadraticISS(
        a=spare / float(eig_P.max()),
        k_v=float(np.linalg.norm(gain.P @ E_v, 2)) ** 2 / c_v if E_v.size else 0.0,
        k=tuple(
            float(np.linalg.norm(gain.P @ gain.L[:, ix], 2)) ** 2 / ci
            for ix, ci in zip(cols, cs, strict=True)
        ),
        lambda_min_P=float(eig_P.min()),
        lambda_max_P=float(eig_P.max()),
        P=gain.P,
        P_origin=gain.origin,
        c_v=float(c_v),
        c=tuple(cs),
        E_v=E_v,
        L=gain.L,
        Q=gain.Q,
        region=gain.region,
    )


def plant_disturbance_matrix(plant: Plant) -> np.ndarray:
    """The plant's disturbance input matrix ``E_v``, read from ``f_p`` at the origin.

    Column ``j`` is ``f_p(0, 0, 0, e_j) - f_p(0, 0, 0, 0)``: exactly ``E_v`` for a plant
    ``x' = f(x, u) + E_v v`` (:func:`~etobs.model.linear_plant`, a python-control
    ``StateSpace``, the robot arm), the form :func:`quadratic_iss_gains` assumes.

    Raises
    ------
    InputError
        When ``f_p`` is not affine in ``v`` at the origin (``f_p(.., e_j) - f_p(.., 0)``
        differs from ``f_p(.., 0) - f_p(.., -e_j)``): no matrix ``E_v`` describes it, so
        quadratic ISS gains built on one do not apply.

    Examples
    --------
    >>> from etobs.model import linear_plant
    >>> plant_disturbance_matrix(linear_plant([[-1.0, 0.0], [0.0, -2.0]], E=[[0.0], [3.0]])).tolist()
    [[0.0], [3.0]]

    """
    zero_x, zero_u = np.zeros(plant.n_x), np.zeros(plant.n_u)
    base = np.asarray(plant.call_f_p(0.0, zero_x, zero_u, np.zeros(plant.n_v)), dtype=float)
    cols = []
    for j, e_j in enumerate(np.eye(plant.n_v)):
        up = np.asarray(plant.call_f_p(0.0, zero_x, zero_u, e_j), dtype=float) - base
        down = base - np.asarray(plant.call_f_p(0.0, zero_x, zero_u, -e_j), dtype=float)
        if not np.allclose(up, down, rtol=1e-9, atol=1e-12 * (1.0 + np.abs(base).max())):
            raise InputError(
                f"the plant {plant.name!r} is not affine in its disturbance v[{j}] at x = 0 (f_p(0, 0, 0, "
                f"+e_{j}) - f_p(0, 0, 0, 0) = {up.tolist()}, f_p(0, 0, 0, 0) - f_p(0, 0, 0, -e_{j}) = "
                f"{down.tolist()}): the quadratic ISS gains assume x' = f(x, u) + E_v v"
            )
        cols.append(up)
    return np.array(cols).T.reshape(plant.n_x, plant.n_v)


def even_split(gain: ObserverGain, n_nodes: int, share: float = 0.5) -> tuple[float, list[float]]:
    """Split constants spending ``share`` of ``lambda_min(Q)`` evenly on ``v`` and the nodes."""
    v.real("share", share, lower=0.0, upper=1.0, lower_open=True, upper_open=True)
    v.integer("n_nodes", n_nodes, lower=1)
    part = share * float(np.linalg.eigvalsh(gain.Q).min()) / (n_nodes + 1)
    return part, [part] * n_nodes
