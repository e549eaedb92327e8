"""Tidy views of an :class:`~etobs.estimation.EstimationResult`: pandas tables, an xarray Dataset, reprs.

This module is imported only when one of them is asked for (``result.to_pandas(...)``,
``result.to_xarray()``, a repr), so ``import etobs`` loads neither pandas nor xarray.

Nodes are numbered as everywhere in etobs: ``0 .. N-1`` the output nodes (node 0 is the
paper's sensor 1), then the input nodes of section 7.3 (``N .. C-1``).
"""

from __future__ import annotations

import html
from collections import Counter
from typing import TYPE_CHECKING, Any

import numpy as np

from etobs.errors import InputError, InputTypeError
from etobs.estimation.metrics import (
    _window,
    max_estimation_error,
    min_inter_event_time,
    transmission_counts,
)

if TYPE_CHECKING:
    import pandas as pd
    import xarray as xr

    from etobs.estimation.result import EstimationResult, Trajectory
    from etobs.hybrid.solution import JumpLog

#: The tables of :meth:`EstimationResult.to_pandas`.
TABLES = ("summary", "transmissions", "grid")
#: The variables of the grid table and of the Dataset, with what they are (the paper's names).
VARIABLES = {
    "x": "plant state",
    "z": "observer state",
    "xhat": "state estimate psi(z)",
    "ybar": "held outputs as the observer holds them (eq. (4))",
    "e": "network-induced error ybar - ytilde (eq. (49))",
    "eta": "each node's eta_i (first entry of its rule state; NaN for stateless rules)",
    "error": "estimation error |x - xhat| (Euclidean norm)",
}
#: Dimension of each variable's components in the Dataset (and their meaning in the grid table).
_COMPONENT_DIM = {
    "x": "state",
    "z": "observer_state",
    "xhat": "state",
    "ybar": "output",
    "e": "output",
    "eta": "node",
    "error": None,
}
#: A repr lists at most this many nodes by name (the rest are counted).
_REPR_NODES = 8


def to_pandas(
    result: EstimationResult, table: str, window: Any = None, variables: Any = None
) -> pd.DataFrame:
    """The table ``table`` of ``result`` (see :meth:`EstimationResult.to_pandas`)."""
    if table not in TABLES:
        raise InputError(f"`table` must be one of {TABLES}; got {table!r}")
    if variables is not None and table != "grid":
        raise InputError(f"`variables` selects the grid table's variables; table {table!r} takes none")
    if table == "summary":
        return summary(result, window)
    if table == "transmissions":
        return transmissions(result, window)
    return grid(result, window, _variables(variables))


def _variables(variables: Any) -> tuple[str, ...]:
    if variables is None:
        return tuple(VARIABLES)
    if not isinstance(variables, str | list | tuple):
        raise InputTypeError(
            f"`variables` must be a name or a list of names from {tuple(VARIABLES)}; "
            f"got {type(variables).__name__}"
        )
    names = (variables,) if isinstance(variables, str) else tuple(variables)
    bad = [n for n in names if n not in VARIABLES]
    if bad or not names:
        raise InputError(
            f"`variables` must be names from {tuple(VARIABLES)}; got {variables!r}"
            + (f" ({', '.join(map(repr, bad))} unknown)" if bad else "")
        )
    return tuple(dict.fromkeys(names))  # each once, in the order given


def _node_frame(result: EstimationResult) -> tuple[list[str], list[str]]:
    """Name and kind (``"output"`` or ``"input"``) of every node, in node order."""
    chans = result.problem.layout.channels
    return [ch.name for ch in chans], ["output" if ch.kind == "y" else "input" for ch in chans]


def summary(result: EstimationResult, window: Any = None) -> pd.DataFrame:
    """One row per run: how it ended, transmissions and inter-event times per node, errors."""
    import pandas as pd

    from etobs.hybrid.status import Status

    lo, hi = _window(window, result)
    pb, sol = result.problem, result.solution
    B, C = result.n_runs, pb.n_channels
    cols: dict[str, Any] = {
        "run": np.arange(B, dtype=np.int64),
        "status": pd.Categorical(result.status_labels(), categories=[s.label for s in Status]),
        "message": result.messages(),
        "backend": pd.Categorical([result.backend] * B),
        "t_final": sol.t_final.astype(float),
        "j_final": sol.j_final.astype(np.int64),
        "n_steps": sol.n_steps.astype(np.int64),
    }
    counts = transmission_counts(result, (lo, hi), nodes="all")
    gaps = min_inter_event_time(result, nodes="all")
    for i in range(C):
        cols[f"transmissions_node{i}"] = counts[:, i]
    for i in range(C):
        cols[f"min_inter_event_time_node{i}"] = gaps[:, i]
    if pb.network is not None:
        for key, arr in result.network_stats().items():
            if key != "sent":  # the sent packets are the transmissions (over the whole run)
                for i in range(C):
                    cols[f"{key}_node{i}"] = arr[:, i]
    q = sol.x_final
    with np.errstate(invalid="ignore", over="ignore"):
        cols["final_error"] = np.linalg.norm(q[:, pb.layout.x] - pb.psi(q[:, pb.layout.z]), axis=-1)
    if sol.grid is not None or sol.grid_max is not None:
        cols["max_error"] = max_estimation_error(result, (lo, hi))
    df = pd.DataFrame(cols)
    names, kinds = _node_frame(result)
    df.attrs.update(
        window=(lo, hi),
        node_names=names,
        node_kinds=kinds,
        backend_reason=result.backend_reason,
        max_error_grid=_grid_description(result),
    )
    return df


def _grid_description(result: EstimationResult) -> str:
    sol = result.solution
    g = sol.grid.t if sol.grid is not None else sol.grid_max.t if sol.grid_max is not None else None
    if g is None:
        return "no grid kept"
    return f"{g.size} points" + (f" on [{g[0]:g}, {g[-1]:g}]" if g.size else "")


def transmissions(result: EstimationResult, window: Any = None) -> pd.DataFrame:
    """One row per transmission (per packet sent, with a network), with the value sent."""
    import pandas as pd

    lo, hi = _window(window, result)
    log = result.transmissions
    keep = (log.t >= lo) & (log.t <= hi)
    names, kinds = _node_frame(result)
    node = log.rule[keep].astype(np.int64)
    df = pd.DataFrame(
        {
            "run": log.run[keep].astype(np.int64),
            "node": node,
            # two nodes may share a name: the categories are the distinct names
            "node_name": pd.Categorical(
                np.asarray(names, dtype=object)[node], categories=list(dict.fromkeys(names))
            ),
            "kind": pd.Categorical.from_codes(
                (np.asarray(kinds)[node] == "input").astype(np.int8), categories=["output", "input"]
            ),
            "t": log.t[keep].astype(float),
            "j": log.j[keep].astype(np.int64),
        }
    )
    for name, col in zip(sent_column_names(result), sent_values(result, log)[keep].T, strict=True):
        df[name] = col
    df.attrs.update(
        node_names=names, window=(lo, hi), hold=result.problem.hold, quantities=sent_quantities(result)
    )
    return df


def sent_column_names(result: EstimationResult) -> list[str]:
    """Names of the value columns of the transmissions table: ``sent_y<k>``, then ``sent_u<k>``."""
    names = result.problem.layout.sent_names
    return [f"sent_y{k}" for k in range(result.problem.plant.n_y)] + sorted(
        (n for n in names if n.startswith("sent_u")), key=lambda n: int(n[6:])
    )


def sent_quantities(result: EstimationResult) -> dict[str, str]:
    """What each value column of the transmissions table holds: ``{"sent_y0": "motor angle [rad]", ...}``.

    The model's names and units (:meth:`~etobs.estimation.EstimationProblem.quantities`),
    else the symbols ``y_1``, ``u_1``.
    """
    out = {}
    for column in sent_column_names(result):
        kind, k = column[5], int(column[6:])
        out[column] = result.problem.quantities(kind)[k].described
    return out


def node_sent_values(result: EstimationResult, log: JumpLog, node: int) -> np.ndarray:
    """The values node ``node``'s transmissions in ``log`` sent: its own components, in order."""
    ch = result.problem.layout.channels[node]
    columns = sent_column_names(result)
    return sent_values(result, log)[:, [columns.index(f"sent_{ch.kind}{k}") for k in ch.index]]


def sent_values(result: EstimationResult, log: JumpLog) -> np.ndarray:
    """The value each transmission of ``log`` sent, one column per ``sent_column_names``.

    NaN in the columns of other nodes' components. Read from the jump log: the solver
    logs the state's *sent* entries just after every jump
    (:attr:`~etobs.estimation.StateLayout.sent_columns`), and after a transmission the
    node's own entries hold what it sent: ``ytilde_i(t_k)`` (eq. (5)), ``ytilde_i -
    yhat_i`` with ``hold="innovation"`` (Remark 3), ``u_k(t_k)`` for an input node.
    """
    pb = result.problem
    where = {n: c for c, n in enumerate(sent_column_names(result))}
    out = np.full((len(log), len(where)), np.nan)
    assert log.x is not None and log.names == pb.layout.sent_names
    offset = 0
    for c, ch in enumerate(pb.layout.channels):
        rows = log.rule == c
        for k, name in enumerate(log.names[offset : offset + ch.size]):
            out[rows, where[name]] = log.x[rows, offset + k]
        offset += ch.size
    return out


def grid(
    result: EstimationResult, window: Any = None, variables: tuple[str, ...] = tuple(VARIABLES)
) -> pd.DataFrame:
    """The grid values in long form: one row per (run, grid point, variable, component)."""
    import pandas as pd

    tr = result.on_grid()  # raises, saying how to keep a grid, when there is none
    lo, hi = _window(window, result)
    sol = result.solution
    assert sol.grid is not None
    pts = np.flatnonzero((sol.grid.t >= lo) & (sol.grid.t <= hi))
    B, G = result.n_runs, pts.size
    parts = []
    for name in variables:
        arr = np.asarray(getattr(tr, name))[:, pts]
        arr = arr[..., None] if arr.ndim == 2 else arr  # the error has no component axis
        k = arr.shape[-1]
        parts.append(
            {
                "run": np.repeat(np.arange(B, dtype=np.int64), G * k),
                "t": np.tile(np.repeat(sol.grid.t[pts], k), B),
                "j": np.repeat(tr.j[:, pts].astype(np.int64).reshape(-1), k),
                "variable": np.full(B * G * k, list(VARIABLES).index(name), dtype=np.int8),
                "component": np.tile(np.arange(k, dtype=np.int64), B * G),
                "value": arr.reshape(-1).astype(float),
            }
        )
    data = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    data["variable"] = pd.Categorical.from_codes(data["variable"], categories=list(VARIABLES))
    # each row's quantity by name and unit (the model's, else the symbol x_1 and no unit), as
    # categorical codes tiled like the components (the strings once each, not once per row)
    texts = {n: _component_text(result, n) for n in variables}
    for col, pick in (("name", 0), ("unit", 1)):
        categories = list(dict.fromkeys(pair[pick] for n in variables for pair in texts[n]))
        codes = [np.tile([categories.index(pair[pick]) for pair in texts[n]], B * G) for n in variables]
        data[col] = pd.Categorical.from_codes(np.concatenate(codes).astype(np.int32), categories=categories)
    df = pd.DataFrame(data)
    df.attrs.update(window=(lo, hi), variables=dict(VARIABLES), node_names=_node_frame(result)[0])
    return df


def _component_text(result: EstimationResult, variable: str) -> list[tuple[str, str]]:
    """``(name, unit)`` of each component of a grid variable, as the grid table and the Dataset show them."""
    pb = result.problem
    if variable == "error":
        return [("|x - xhat|", "")]
    if variable == "eta":
        return [(name, "") for name in pb.channel_names]
    return [(q.text, q.unit) for q in pb.quantities(variable)]


def to_xarray(result: EstimationResult) -> xr.Dataset:
    """The grid values as an ``xarray.Dataset`` (see :meth:`EstimationResult.to_xarray`)."""
    import xarray as xr

    tr = result.on_grid()  # raises, saying how to keep a grid, when there is none
    sol, pb = result.solution, result.problem
    assert sol.grid is not None
    names, kinds = _node_frame(result)
    data = {
        name: (
            ("run", "time") if _COMPONENT_DIM[name] is None else ("run", "time", _COMPONENT_DIM[name]),
            np.asarray(getattr(tr, name), dtype=float),
            {"description": desc},
        )
        for name, desc in VARIABLES.items()
    }
    data["j"] = (("run", "time"), tr.j.astype(np.int64), {"description": "jump counter (-1: not reached)"})
    coords = {
        "run": np.arange(result.n_runs),
        "time": sol.grid.t,
        "state": np.arange(pb.plant.n_x),
        "observer_state": np.arange(pb.observer.n_z),
        "output": np.arange(pb.plant.n_y),
        "state_name": ("state", [n for n, _ in _component_text(result, "x")]),
        "state_unit": ("state", [u for _, u in _component_text(result, "x")]),
        "observer_state_name": ("observer_state", [n for n, _ in _component_text(result, "z")]),
        "observer_state_unit": ("observer_state", [u for _, u in _component_text(result, "z")]),
        "output_name": ("output", [n for n, _ in _component_text(result, "ybar")]),
        "output_unit": ("output", [u for _, u in _component_text(result, "ybar")]),
        "node": np.arange(pb.n_channels),
        "node_name": ("node", names),
        "node_kind": ("node", kinds),
        "status": ("run", result.status_labels()),
        "message": ("run", result.messages()),
    }
    attrs = {
        "backend": result.backend,
        "backend_reason": result.backend_reason,
        "t_span": tuple(float(t) for t in sol.t_span),
        "hold": pb.hold,
        "units": "those of the model: the coordinates state_unit, observer_state_unit, output_unit "
        "(empty where the model gives none)",
        "nodes": "numbered from 0 (node 0 is the paper's sensor 1): output nodes, then input nodes",
        "not_reached": "grid points after a run stopped, or outside the horizon, hold NaN with j = -1",
    }
    return xr.Dataset(data, coords=coords, attrs=attrs)


# -- reprs ------------------------------------------------------------------------------


def _result_lines(result: EstimationResult) -> list[tuple[str, str]]:
    """The repr's rows: ``(label, text)``."""
    sol = result.solution
    t0, t1 = sol.t_span
    status = ", ".join(f"{n} {s}" for s, n in Counter(result.status_labels()).items())
    names = [ch.name for ch in result.problem.layout.channels]
    counts = result.transmissions.counts(result.n_runs, len(names)).sum(axis=0)
    shown = [f"{i} {n!r}: {int(c)}" for i, (n, c) in enumerate(zip(names, counts, strict=True))]
    if len(shown) > _REPR_NODES:
        shown = [*shown[:_REPR_NODES], f"... ({len(shown) - _REPR_NODES} more nodes)"]
    kept = ["the transmission log"]
    if sol.arcs is not None:
        kept.append("full arcs (.arc(run))")
    if sol.grid is not None:
        kept.append(f"a grid of {_grid_description(result)} (.on_grid(), .to_xarray())")
    if sol.grid_max is not None:
        kept.append(f"max |x - xhat| over a grid of {_grid_description(result)}")
    rows = [
        ("runs", f"{result.n_runs} on t in [{t0:g}, {t1:g}]"),
        ("status", status or "no runs"),
        ("transmissions", "(sum over runs) " + ", ".join(shown)),
        ("backend", f"{result.backend} ({result.backend_reason})".replace(" ()", "")),
        ("kept", ", ".join(kept)),
    ]
    rows += [("note", n) for n in result.notes]
    rows.append(("tables", '.to_pandas("summary" | "transmissions" | "grid")'))
    return rows


def result_repr(result: EstimationResult) -> str:
    """A few lines: runs, status counts, transmissions per node, backend, what was kept."""
    return "EstimationResult\n" + "\n".join(f"  {k}: {v}" for k, v in _result_lines(result))


def _html_table(title: str, rows: list[tuple[str, str]]) -> str:
    left = "style='text-align:left'"
    body = "".join(
        f"<tr><th {left}>{html.escape(k)}</th><td {left}>{html.escape(v)}</td></tr>" for k, v in rows
    )
    return f"<table><caption {left}><b>{html.escape(title)}</b></caption>{body}</table>"


def result_html(result: EstimationResult) -> str:
    """The repr's rows as an HTML table (for notebooks)."""
    return _html_table("EstimationResult", _result_lines(result))


def _trajectory_lines(tr: Trajectory) -> list[tuple[str, str]]:
    t = np.asarray(tr.t)
    if t.ndim >= 2:
        what = f"{t.shape[0]} runs x {t.shape[1]} grid points"
    else:
        what = f"one arc of {t.shape[0]} points"
    span = "no points" if t.size == 0 else f"[{np.nanmin(t):g}, {np.nanmax(t):g}]"
    j = np.asarray(tr.j)
    jumps = f", j up to {int(j.max())}" if j.size else ""
    shapes = ", ".join(f"{n} {getattr(tr, n).shape}" for n in ("x", "z", "xhat", "ybar", "e", "eta"))
    return [("points", what), ("t", span + jumps), ("arrays", shapes)]


def trajectory_repr(tr: Trajectory) -> str:
    """A few lines: how many points, the time span, the arrays' shapes."""
    return "Trajectory\n" + "\n".join(f"  {k}: {v}" for k, v in _trajectory_lines(tr))


def trajectory_html(tr: Trajectory) -> str:
    """The repr's rows as an HTML table."""
    return _html_table("Trajectory", _trajectory_lines(tr))
