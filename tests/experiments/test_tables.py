"""Tidy tables: per-node statistics in the aggregate, and the Parquet twin of every CSV."""

import io

import pandas as pd
import pyarrow.parquet as pq
import pytest

from etobs.experiments.tables import aggregate, run_rows, to_csv, to_parquet, write_table


def record(run, counts, mins, status="completed", error=0.5, packets=None):
    return {
        "run": run,
        "status": status,
        "transmissions": counts,
        "error": error,
        "min_inter_event_time": mins,
        "x0": [0.1 * run],
        "steps": 10 + run,
        "packets": packets,
        "not_applied": None if packets is None else [0] * len(packets),
    }


def test_the_aggregate_has_every_nodes_counts_and_minimum_inter_event_time():
    recs = [
        record(0, [3, 10], [0.2, 0.05]),
        record(1, [5, 14], [None, 0.04]),  # node 0 sent fewer than twice in its window
        record(2, [99, 99], [0.001, 0.001], status="max_jumps"),  # not completed: left out
    ]
    runs = run_rows([({"row": 0, "scenario": "a"}, {"sigma": [1.0, 2.0]}, recs)])
    assert [r["transmissions_node1"] for r in runs] == [10, 14, 99]
    assert runs[0]["transmissions"] == 13 and runs[0]["sigma2"] == 2.0
    [line] = aggregate(
        runs, ["sigma1", "sigma2"], [({"row": 0, "scenario": "a"}, {"sigma1": 1.0, "sigma2": 2.0})]
    )
    assert (line["runs"], line["completed"]) == (3, 2)
    assert line["transmissions_node0_mean"] == 4.0 and line["transmissions_node1_mean"] == 12.0
    assert (line["transmissions_node1_min"], line["transmissions_node1_max"]) == (10, 14)
    assert isinstance(line["transmissions_node1_min"], int)  # a count stays an integer
    assert line["min_inter_event_time_node0_min"] == 0.2  # the run with a value only
    assert line["min_inter_event_time_node0_std"] is None  # one value
    assert line["min_inter_event_time_node1_min"] == 0.04
    assert "packets_node0_mean" not in line  # the ideal network sends no packets


def test_a_group_without_runs_has_every_column_and_no_values():
    runs = run_rows([({"rule": "r", "network": "lossy"}, {}, [record(0, [2], [0.3], packets=[4])])])
    assert runs[0]["packets_node0"] == 4 and runs[0]["not_applied_node0"] == 0
    keys = [({"rule": "r", "network": "lossy"}, {}), ({"rule": "s", "network": "lossy"}, {})]
    full, empty = aggregate(runs, (), keys)
    assert full["packets_node0_mean"] == 4.0
    assert empty["runs"] == 0 and list(empty) == list(full)
    assert all(empty[k] is None for k in full if k.endswith(("_mean", "_std", "_min", "_max")))


def test_parquet_columns_are_typed_and_read_back_as_the_csv():
    rows = [
        {
            "row": 0,
            "name": "a",
            "k": 1,
            "mixed": 1,
            "flag": True,
            "x": 0.5,
            "empty": None,
            "status": "completed",
        },
        {
            "row": 1,
            "name": "b",
            "k": 2.5,
            "mixed": "two",
            "flag": False,
            "x": None,
            "empty": None,
            "status": "zeno",
        },
        {"row": 2, "name": "c", "k": 3, "mixed": [1, 2], "flag": None, "x": 1e300, "status": "completed"},
    ]
    table = pq.read_table(io.BytesIO(to_parquet(rows)))
    types = {f.name: str(f.type) for f in table.schema}
    assert types == {
        "row": "int64",
        "name": "string",
        "k": "double",  # integers and floats together
        "mixed": "string",  # numbers, text and a list: the text the CSV holds
        "flag": "bool",
        "x": "double",
        "empty": "double",  # nothing in it: as a CSV reader sees an empty column
        "status": "string",
    }
    assert table.column("mixed").to_pylist() == ["1", "two", "[1, 2]"]
    assert table.column("flag").to_pylist() == [True, False, None]
    from_csv = pd.read_csv(io.StringIO(to_csv(rows)))
    from_parquet = table.to_pandas()
    assert list(from_parquet.columns) == list(from_csv.columns)
    for col in ("row", "name", "k", "x", "empty", "status"):
        pd.testing.assert_series_equal(from_parquet[col], from_csv[col], check_dtype=True)


def test_an_integer_beyond_int64_is_kept_as_text_not_wrapped():
    table = pq.read_table(io.BytesIO(to_parquet([{"seed": 2**70}, {"seed": 1}])))
    assert table.column("seed").to_pylist() == [str(2**70), "1"]


@pytest.mark.parametrize("rows", [[], [{"a": 1}]])
def test_write_table_writes_both_files_atomically(tmp_path, rows):
    write_table(tmp_path, "runs", rows)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["runs.csv", "runs.parquet"]  # no temporary left
    assert len(pq.read_table(tmp_path / "runs.parquet")) == len(rows)
