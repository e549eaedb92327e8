"""Tidy tables of a sweep: one row per run, and aggregates per parameter row and scenario.

List-valued parameters are flattened with 1-based suffixes as in the paper
(``sigma = [600, 800]`` gives ``sigma1, sigma2``); per-node columns use the code's
0-based node index (``transmissions_node0``).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np


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


def run_rows(groups: Iterable[tuple[int, str, dict[str, Any], list[dict[str, Any]]]]) -> list[dict[str, Any]]:
    """One flat dictionary per run from ``(row, scenario, params, records)`` groups."""
    rows = []
    for row, scenario, params, records in groups:
        flat = flatten_params(params)
        for rec in sorted(records, key=lambda r: r["run"]):
            line: dict[str, Any] = {"row": row, "scenario": scenario, "run": rec["run"], **flat}
            line["status"] = rec["status"]
            line["transmissions"] = sum(rec["transmissions"])
            for i, c in enumerate(rec["transmissions"]):
                line[f"transmissions_node{i}"] = c
            line["error"] = rec["error"]
            for i, m in enumerate(rec["min_inter_event_time"]):
                line[f"min_inter_event_time_node{i}"] = m
            for i, x in enumerate(rec["x0"], start=1):
                line[f"x0_{i}"] = x
            line["steps"] = rec["steps"]
            rows.append(line)
    return rows


def _stats(values: Sequence[float | None]) -> dict[str, float | None]:
    arr = np.array([v for v in values if v is not None and math.isfinite(v)], dtype=float)
    if arr.size == 0:
        return {"mean": None, "std": None, "min": None, "max": None}
    std = float(arr.std(ddof=1)) if arr.size > 1 else None
    return {"mean": float(arr.mean()), "std": std, "min": float(arr.min()), "max": float(arr.max())}


def aggregate(
    runs: list[dict[str, Any]],
    param_names: Sequence[str],
    keys: Sequence[tuple[int, str, dict[str, Any]]],
) -> list[dict[str, Any]]:
    """Mean, sample std, min and max of transmissions and error per (row, scenario).

    ``keys`` lists every ``(row, scenario, flat params)`` of the sweep, so a group with no
    run present still gets a line (``runs = 0``, statistics ``None``). Statistics use the
    completed runs only; ``runs`` and ``completed`` count them; the std of fewer than two
    values is ``None``.
    """
    groups: dict[tuple[int, str], list[dict[str, Any]]] = {(r, s): [] for r, s, _ in keys}
    for r in runs:
        groups[(r["row"], r["scenario"])].append(r)
    params = {(r, s): p for r, s, p in keys}
    out = []
    for (row, scenario), items in groups.items():
        ok = [r for r in items if r["status"] == "completed"]
        line: dict[str, Any] = {"row": row, "scenario": scenario}
        line.update({k: params[(row, scenario)].get(k) for k in param_names})
        line["runs"] = len(items)
        line["completed"] = len(ok)
        for metric in ("transmissions", "error"):
            for stat, value in _stats([r[metric] for r in ok]).items():
                line[f"{metric}_{stat}"] = value
        out.append(line)
    return out


def to_csv(rows: list[dict[str, Any]]) -> str:
    """CSV text with the union of the rows' keys as header, in first-seen order."""
    header: list[str] = []
    for r in rows:
        header += [k for k in r if k not in header]
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=header, lineterminator="\n")
    writer.writeheader()
    for r in rows:
        writer.writerow({k: "" if r.get(k) is None else r.get(k) for k in header})
    return buf.getvalue()


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
    from etobs.hybrid.status import Status, status_message

    out = []
    for label in sorted(set(statuses) - {"completed"}):
        try:
            out.append(f"`{label}`: {status_message(Status[label.upper()])}")
        except KeyError:  # a record written by another version
            out.append(f"`{label}`: a status this version of etobs does not know")
    return out
