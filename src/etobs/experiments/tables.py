"""Tidy tables of an experiment: one row per run, and aggregates per group.

A group is a sweep's (row, scenario) or a comparison's (rule, network); its labels lead
each line. List-valued parameters are flattened with 1-based suffixes as in the paper
(``sigma = [600, 800]`` gives ``sigma1, sigma2``); per-node columns use the code's
0-based node index over all nodes, output nodes then input nodes
(``transmissions_node0``), as runs are stored.

Every table is written twice (:func:`write_table`): as CSV, and as a Parquet file with
the same columns, typed (integers, floats, booleans, strings; a missing value is null).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError
from etobs.experiments.store import atomic_write

#: Per-run metrics summarised by :func:`aggregate`, each also per node (``NAME_node0``...),
#: and whether its values are counts (their minimum and maximum stay integers).
METRICS = {
    "transmissions": True,
    "error": False,
    "min_inter_event_time": False,
    "packets": True,
    "not_applied": True,
}


def flatten_params(params: dict[str, Any]) -> dict[str, Any]:
    """``{"sigma": [600, 800], "noise": True}`` -> ``{"sigma1": 600, "sigma2": 800, "noise": True}``."""
    out: dict[str, Any] = {}
    for k, v in params.items():
        if isinstance(v, (list, tuple)):
            for i, item in enumerate(v, start=1):
                out[f"{k}{i}"] = item
        else:
            out[k] = v
    return out


def run_rows(
    groups: Iterable[tuple[dict[str, Any], dict[str, Any], list[dict[str, Any]]]],
) -> list[dict[str, Any]]:
    """One flat dictionary per run from ``(labels, params, records)`` groups.

    ``labels`` name the group (``{"row": 0, "scenario": "noise"}``, ``{"rule": ...,
    "network": ...}``) and lead each line, then ``run`` and the flattened ``params``;
    ``records`` are the group's stored runs (:func:`~etobs.experiments.runner.run_task`).
    A node's ``packets`` and ``not_applied`` columns appear only with a network.
    """
    rows = []
    for labels, params, records in groups:
        flat = flatten_params(params)
        for rec in sorted(records, key=lambda r: r["run"]):
            line: dict[str, Any] = {**labels, "run": rec["run"], **flat}
            line["status"] = rec["status"]
            line["transmissions"] = sum(rec["transmissions"])
            line.update(_per_node("transmissions", rec["transmissions"]))
            line["error"] = rec["error"]
            line.update(_per_node("min_inter_event_time", rec["min_inter_event_time"]))
            for name in ("packets", "not_applied"):  # None on the ideal network
                line.update(_per_node(name, rec.get(name) or ()))
            for i, x in enumerate(rec["x0"], start=1):
                line[f"x0_{i}"] = x
            line["steps"] = rec["steps"]
            rows.append(line)
    return rows


def _per_node(name: str, values: Iterable[Any]) -> dict[str, Any]:
    return {f"{name}_node{i}": v for i, v in enumerate(values)}


def _is_metric(column: str) -> bool:
    """A per-run metric column of :func:`run_rows` (a parameter may take none of these names)."""
    base, _, node = column.partition("_node")
    return column in ("transmissions", "error") or (base in METRICS and node.isdigit())


def _stats(values: Sequence[float | None], *, counts: bool = False) -> dict[str, float | None]:
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None}
    std = float(arr.std(ddof=1)) if arr.size > 1 else None
    lo, hi = (int(v) if counts else float(v) for v in (arr.min(), arr.max()))
    return {"mean": float(arr.mean()), "std": std, "min": lo, "max": hi}


def aggregate(
    runs: list[dict[str, Any]],
    param_names: Sequence[str],
    keys: Sequence[tuple[dict[str, Any], dict[str, Any]]],
) -> list[dict[str, Any]]:
    """Mean, sample std, min and max of every per-run metric, per group.

    ``keys`` lists every group as ``(labels, flat params)`` (the labels as in
    :func:`run_rows`), so a group with no run present still gets a line (``runs = 0``,
    statistics ``None``). A metric column ``X`` of the runs (``transmissions``,
    ``transmissions_node0``, ``error``, ``min_inter_event_time_node0``, ...) gives
    ``X_mean``, ``X_std``, ``X_min``, ``X_max``, over the completed runs where ``X`` has a
    value (a node's minimum inter-event time needs two of its transmissions). ``runs``
    and ``completed`` count the runs; the std of fewer than two values is ``None``; the
    minimum and maximum of counts are integers.
    """
    metrics: list[str] = []
    for r in runs:
        metrics += [k for k in r if _is_metric(k) and k not in metrics]
    by = tuple(keys[0][0]) if keys else ()
    groups: dict[tuple[Any, ...], list[dict[str, Any]]] = {tuple(lab.values()): [] for lab, _ in keys}
    for r in runs:
        groups[tuple(r[k] for k in by)].append(r)
    out = []
    for labels, params in keys:
        items = groups[tuple(labels.values())]
        ok = [r for r in items if r["status"] == "completed"]
        line: dict[str, Any] = {**labels}
        line.update({k: params.get(k) for k in param_names})
        line["runs"] = len(items)
        line["completed"] = len(ok)
        for metric in metrics:
            counts = METRICS[metric.partition("_node")[0]]
            for stat, value in _stats([r.get(metric) for r in ok], counts=counts).items():
                line[f"{metric}_{stat}"] = value
        out.append(line)
    return out


def columns(rows: Iterable[dict[str, Any]]) -> list[str]:
    """The union of the rows' keys, in first-seen order (the tables' header)."""
    header: dict[str, None] = {}
    for r in rows:
        header.update(dict.fromkeys(r))
    return list(header)


def to_csv(rows: list[dict[str, Any]]) -> str:
    """CSV text with the union of the rows' keys as header, in first-seen order."""
    header = columns(rows)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=header, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: "" if r.get(k) is None else r.get(k) for k in header})
    return buf.getvalue()


def to_parquet(rows: list[dict[str, Any]]) -> bytes:
    """Parquet bytes of the rows, with the columns of :func:`to_csv`, each typed.

    A column is ``bool`` when every value present is a boolean, ``int64`` when every one
    is an integer, ``double`` when they are numbers, ``string`` when they are strings,
    and otherwise (an integer beyond 64 bits too) the text the CSV holds; ``None`` is
    null (a column with nothing in it is a ``double`` of nulls, as a CSV reader sees it).
    """
    import pyarrow.parquet as pq

    buf = io.BytesIO()
    pq.write_table(to_arrow(rows), buf)
    return buf.getvalue()


def to_arrow(rows: list[dict[str, Any]]) -> Any:
    """The rows as a ``pyarrow.Table``, typed as in :func:`to_parquet`."""
    import pyarrow as pa

    return pa.table({k: _arrow_column([r.get(k) for r in rows]) for k in columns(rows)})


def to_frame(table: Any, tables: dict[str, list[dict[str, Any]]]) -> Any:
    """The rows ``tables[table]`` as a ``pandas.DataFrame``, as ``pandas.read_parquet`` reads them.

    ``table`` is the argument of a result's ``to_pandas``: a key of ``tables``, else an
    error naming the choices.
    """
    if not isinstance(table, str) or table not in tables:
        raise InputError(f"`table` must be one of {', '.join(map(repr, tables))}; got {table!r}")
    return to_arrow(tables[table]).to_pandas()


def _arrow_column(values: list[Any]) -> Any:
    import pyarrow as pa

    values = [v.item() if isinstance(v, np.generic) else v for v in values]
    present = [v for v in values if v is not None]
    kinds = {bool if isinstance(v, bool) else int if isinstance(v, int) else type(v) for v in present}
    if kinds <= {bool} and present:
        return pa.array(values, type=pa.bool_())
    in_range = all(-(2**63) <= v < 2**63 for v in present if isinstance(v, int))  # else: text, exact
    if kinds <= {int} and present and in_range:
        return pa.array(values, type=pa.int64())
    if kinds <= {int, float} and in_range:
        return pa.array([None if v is None else float(v) for v in values], type=pa.float64())
    if kinds <= {str}:
        return pa.array(values, type=pa.string())
    return pa.array([None if v is None else str(v) for v in values], type=pa.string())  # as in the CSV


def load_writers() -> None:
    """Import what :func:`write_table` needs, so that a sweep can do it while its workers compute.

    pyarrow (0.2 s), and pandas, which pyarrow imports at its first conversion when it
    is installed (0.3 s): half a second of Table 1's tail before. A failure is left for
    :func:`write_table` to raise where it matters.
    """
    try:
        import pyarrow as pa
        import pyarrow.parquet

        pa.array([0])
    except Exception:  # raised again, with its context, by the writer
        pass


def write_table(folder: Path, name: str, rows: list[dict[str, Any]]) -> None:
    """Write ``folder/name.csv`` and its typed twin ``folder/name.parquet``, each atomically."""
    atomic_write(folder / f"{name}.csv", to_csv(rows))
    atomic_write(folder / f"{name}.parquet", to_parquet(rows))


def to_markdown(rows: list[dict[str, Any]], columns: Sequence[str], digits: int = 4) -> str:
    """A Markdown table of ``columns``; floats with ``digits`` significant digits."""

    def fmt(v: Any) -> str:
        if v is None:
            return "n/a"
        if isinstance(v, float):
            return f"{v:.{digits}g}"
        return str(v)

    lines = ["| " + " | ".join(columns) + " |", "|" + "---|" * len(columns)]
    lines += ["| " + " | ".join(fmt(r.get(c)) for c in columns) + " |" for r in rows]
    return "\n".join(lines) + "\n"


def not_completed(statuses: Iterable[str]) -> str:
    """How many runs ended with each status other than ``completed``: ``"2 max_jumps, 1 zeno"``.

    ``""`` when every run completed.
    """
    counts: dict[str, int] = {}
    for s in statuses:
        if s != "completed":
            counts[s] = counts.get(s, 0) + 1
    return ", ".join(f"{n} {s}" for s, n in sorted(counts.items()))


def status_notes(statuses: Iterable[str]) -> list[str]:
    """One line per status other than ``completed`` that occurs: what it means and how to fix it."""
    from etobs.estimation.result import STATUS_ADVICE
    from etobs.hybrid.status import Status, status_message

    out = []
    for label in sorted(set(statuses) - {"completed"}):
        try:
            out.append(f"`{label}`: {status_message(Status[label.upper()], advice=STATUS_ADVICE)}")
        except KeyError:  # a record written by another version
            out.append(f"`{label}`: a status this version of etobs does not know")
    return out
