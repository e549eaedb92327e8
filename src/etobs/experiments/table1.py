"""The paper's Table 1: our sweep next to the published values.

The published values ship in ``etobs/experiments/data/table1_paper.csv`` (the paper's
Table 1 as data) and the sweep spec in ``data/table1.toml`` (also ``examples/table1.toml``).

Statistical check of the transmission column: the paper's mean is itself an average
over 100 random initial states drawn independently of ours, so the difference of the
two means has standard error ``s * sqrt(1/n + 1/100)``, with ``s`` our sample standard
deviation (the paper gives none) and ``n`` our number of runs. A cell is *within the
statistical uncertainty* when ``|z| <= 3`` for ``z = (ours - paper) / se``.
"""

from __future__ import annotations

import csv
import io
import math
from importlib import resources
from typing import Any

from etobs.experiments.spec import SweepSpec, parse_spec
from etobs.experiments.sweep import SweepResult
from etobs.experiments.tables import to_markdown

PAPER_RUNS = 100
Z_LIMIT = 3.0
PARAMS = ("sigma1", "sigma2", "eps1", "eps2", "a1", "a2", "ell1", "ell2")
COLUMNS = (
    *PARAMS,
    "scenario",
    "transmissions_mean",
    "transmissions_std",
    "error_mean",
    "error_std",
    "paper_transmissions",
    "paper_error",
    "runs",
    "transmissions_se",
    "transmissions_z",
    "within_uncertainty",
)


def _data(name: str) -> str:
    return resources.files("etobs.experiments").joinpath("data", name).read_text()


def table1_spec() -> SweepSpec:
    """The packaged Table 1 sweep spec."""
    import tomllib

    return parse_spec(tomllib.loads(_data("table1.toml")))


def paper_table() -> list[dict[str, float]]:
    """The paper's Table 1, one dictionary per row (``l1, l2`` renamed ``ell1, ell2``)."""
    rows = []
    for r in csv.DictReader(io.StringIO(_data("table1_paper.csv"))):
        rows.append({("ell" + k[1:] if k in ("l1", "l2") else k): float(v) for k, v in r.items()})
    return rows


def compare(result: SweepResult) -> list[dict[str, Any]]:
    """One line per (row, scenario): ours, the paper's, and the z-score of transmissions."""
    paper = paper_table()
    out = []
    for agg in result.aggregate:
        p = paper[agg["row"]]
        if any(not math.isclose(float(agg[k]), p[k]) for k in PARAMS):
            raise ValueError(f"row {agg['row']} of the sweep does not have the paper's parameters")
        sc = agg["scenario"]
        line = {k: agg[k] for k in PARAMS}
        line.update(
            scenario=sc,
            transmissions_mean=agg["transmissions_mean"],
            transmissions_std=agg["transmissions_std"],
            error_mean=agg["error_mean"],
            error_std=agg["error_std"],
            paper_transmissions=p[f"transmissions_{sc}"],
            paper_error=p[f"err_{sc}"],
            runs=agg["completed"],
        )
        n, s = agg["completed"], agg["transmissions_std"]
        if n > 1 and s is not None and agg["transmissions_mean"] is not None:
            se = s * math.sqrt(1.0 / n + 1.0 / PAPER_RUNS)
            z = (agg["transmissions_mean"] - line["paper_transmissions"]) / se if se > 0 else math.inf
            line.update(transmissions_se=se, transmissions_z=z, within_uncertainty=abs(z) <= Z_LIMIT)
        else:
            line.update(transmissions_se=None, transmissions_z=None, within_uncertainty=None)
        out.append(line)
    return out


def markdown(lines: list[dict[str, Any]], result: SweepResult) -> str:
    """``table1.md``: ours next to the paper's, with the check of each transmission cell."""
    cols = [
        "sigma1",
        "sigma2",
        "eps1",
        "eps2",
        "a1",
        "a2",
        "ell1",
        "ell2",
        "scenario",
        "transmissions_mean",
        "transmissions_se",
        "paper_transmissions",
        "transmissions_z",
        "within_uncertainty",
        "error_mean",
        "paper_error",
    ]
    outside = [ln for ln in lines if ln["within_uncertainty"] is False]
    head = [
        "# Table 1 of the paper, reproduced",
        "",
        f"{result.spec.initial_states.runs} random initial states per row (seed "
        f"{result.spec.initial_states.seed}), the same for every row and scenario; horizon "
        f"{result.spec.t_end:g} s. `transmissions_se` is the standard error of the difference "
        f"between our mean and the paper's (both over random initial states); a cell is within "
        f"the statistical uncertainty when |z| <= {Z_LIMIT:g}. The error is the mean over runs of "
        f"max |x - xhat| on [20, 30] (1 ms grid).",
        "",
        f"Transmission cells outside the uncertainty: {len(outside)} of {len(lines)}.",
        "",
    ]
    return "\n".join(head) + to_markdown(lines, cols)
