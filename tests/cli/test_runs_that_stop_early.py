"""A sweep with eps = 1e-300 and a comparison with period 1e-7 end with a named status per
run, and the CLI says how many runs stopped early, with which status and what it means.

In the audit of issue 14 both were killed at the time limit with no output. The solver now
ends each run at its jump limit; here the limit is lowered (``[solver] max_jumps``) so the
tests stay cheap, the path through the CLI being the same.
"""

import csv

import pytest

from etobs.cli.main import main

COMMON = """
[system]
factory = "tests.estimation.linear:factory"
{params}
[initial_states]
low = [-1.0, -1.0]
high = [1.0, 1.0]
runs = 2
seed = 3
[horizon]
t_end = 30.0
[solver]
max_jumps = 500
"""
STOPPED = {"max_jumps", "zeno"}


def test_a_sweep_with_a_tiny_eps_ends_with_a_status_per_run(tmp_path, capsys):
    spec = tmp_path / "eps.toml"
    spec.write_text('name = "tiny_eps"' + COMMON.format(params="fixed = { eps = 1e-300 }"))
    out = tmp_path / "out"
    assert main(["sweep", str(spec), "--out", str(out), "--executor", "serial"]) == 0  # every run present
    with open(out / "runs.csv") as fh:
        statuses = [row["status"] for row in csv.DictReader(fh)]
    assert len(statuses) == 2 and set(statuses) <= STOPPED
    printed = capsys.readouterr().out
    report = (out / "report.md").read_text()
    assert report in printed
    counts = ", ".join(f"{statuses.count(s)} {s}" for s in sorted(set(statuses)))
    assert f"Runs not completed: {counts} (see `status` in runs.csv)." in report
    assert "increase `SolverOptions(max_jumps=...)` if the jumps are expected" in report or "zeno" in report


@pytest.mark.parametrize("backend", ["engine", "scipy"])
def test_a_comparison_with_a_tiny_period_ends_with_a_status_per_run(backend, tmp_path, capsys):
    spec = tmp_path / "period.toml"
    rules = '[[rules]]\nname = "period 1e-7"\nkind = "periodic"\nperiod = 1e-7\n'
    spec.write_text('name = "tiny_period"' + COMMON.format(params="") + rules)
    out = tmp_path / "out"
    argv = [
        "compare",
        str(spec),
        "--out",
        str(out),
        "--executor",
        "serial",
        "--no-plot",
        "--backend",
        backend,
    ]
    assert main(argv) == 0
    captured = capsys.readouterr()
    assert "period 1e-7 / ideal: 0/2 runs completed (2 max_jumps)" in captured.err
    table = (out / "comparison.md").read_text()
    assert "Not completed: period 1e-7 / ideal: 2 max_jumps." in table
    assert "- `max_jumps`: the run reached its limit on the number of jumps" in table
    assert table.split("\n", 2)[2] in captured.out
