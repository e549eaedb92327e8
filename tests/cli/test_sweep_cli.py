import json
import re

import pytest

from etobs.cli.main import main
from etobs.experiments import SweepResult, parse_spec
from etobs.experiments.table1 import COLUMNS, compare, markdown, paper_table, table1_spec

from ..experiments.conftest import FACTORY


def write_spec(path, runs=3, extra=""):
    path.write_text(
        f'name = "cli"\n[system]\nfactory = "{FACTORY}"\n[[rows]]\nk = 1.0\n{extra}'
        f"[initial_states]\nlow = [-1.0]\nhigh = [1.0]\nruns = {runs}\nseed = 1\n[horizon]\nt_end = 1.0\n"
    )
    return path


def test_sweep_command(tmp_path, capsys):
    spec = write_spec(tmp_path / "s.toml")
    code = main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--executor", "serial", "--no-progress"])
    out = capsys.readouterr().out
    assert code == 0
    assert "3 of 3 runs present (3 computed now, 0 reused); 0 failed chunks" in out
    assert (tmp_path / "o" / "runs.csv").exists()
    code = main(
        [
            "sweep",
            str(spec),
            "--out",
            str(tmp_path / "o"),
            "--executor",
            "serial",
            "--runs",
            "4",
            "--no-progress",
        ]
    )
    assert code == 0
    assert "4 of 4 runs present (1 computed now, 3 reused)" in capsys.readouterr().out


def test_progress_flag_forces_the_bar_on_or_off(tmp_path, capsys):
    spec = write_spec(tmp_path / "s.toml", extra="[[rows]]\nk = 2.0\nfail = true\n")
    argv = ["sweep", str(spec), "--executor", "serial", "--chunk-size", "1"]
    assert main([*argv, "--out", str(tmp_path / "on"), "--progress"]) == 1
    err = capsys.readouterr().err
    assert "cli: 100%" in err and "6/6" in err and "3 failed" in err  # tqdm's bar, failed runs in it
    assert "ETA" not in err and "nan" not in err  # not the hand-written line
    assert main([*argv, "--out", str(tmp_path / "off"), "--no-progress"]) == 1
    assert "%|" not in capsys.readouterr().err
    assert main([*argv, "--out", str(tmp_path / "default")]) == 1  # captured stderr: not a terminal
    assert "%|" not in capsys.readouterr().err


@pytest.mark.parametrize(
    ("flag", "resolved"), [("numba", "engine"), ("engine", "engine"), ("scipy", "scipy")]
)
def test_sweep_command_backend_and_its_earlier_names(tmp_path, capsys, flag, resolved):
    spec = write_spec(tmp_path / "s.toml", runs=2)
    argv = ["sweep", str(spec), "--out", str(tmp_path / "o"), "--executor", "serial", "--no-progress"]
    assert main([*argv, "--backend", flag]) == 0
    assert json.loads((tmp_path / "o" / "spec.json").read_text())["resolved"]["backend"] == resolved


def test_sweep_command_failures_exit_non_zero(tmp_path, capsys):
    spec = write_spec(tmp_path / "s.toml", extra="[[rows]]\nk = 2.0\nfail = true\n")
    code = main(["sweep", str(spec), "--out", str(tmp_path / "o"), "--executor", "serial", "--no-progress"])
    captured = capsys.readouterr()
    assert code == 1
    assert "failed: runs 0..2" in captured.err and "this row fails on purpose" in captured.err


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--workers", "0"], r"argument --workers: must be a positive integer; got '0'"),
        # a typo (1000 for 10) spawned up to 1000 processes of ~140 MB each, as many as there were chunks
        (
            ["--workers", "1000"],
            r"`workers` = 1000 is more than 4 per core of this machine's \d+ .*: at most \d+",
        ),
        (["--executor", "serial", "--scheduler", "tcp://127.0.0.1:1"], r"--scheduler needs --executor dask"),
    ],
)
def test_sweep_command_bad_arguments(tmp_path, capsys, argv, match):
    spec = write_spec(tmp_path / "s.toml")
    with pytest.raises(SystemExit) as info:
        main(["sweep", str(spec), "--out", str(tmp_path / "o"), *argv])
    assert info.value.code == 2
    assert re.search(match, capsys.readouterr().err)


def test_bad_spec_is_one_clear_line(tmp_path, capsys):
    spec = tmp_path / "s.toml"
    spec.write_text('[system]\nfactory = "robot_arm"\n[horizon]\nt_end = 1.0\n')
    with pytest.raises(SystemExit) as info:
        main(["sweep", str(spec)])
    assert info.value.code == 2
    assert capsys.readouterr().err.strip() == (
        f"etobs: error: {spec}: missing key `initial_states`: expected a table; the spec has keys horizon, system"
    )


def test_table1_comparison_columns_and_statistics():
    paper = paper_table()
    assert len(paper) == 13 and paper[0]["transmissions_with_v_m"] == 163 and paper[12]["ell1"] == 100
    spec = table1_spec().with_runs(4)
    # A synthetic result: row 0 exactly at the paper's value, row 1 far from it.
    aggregate = []
    for r, p in enumerate(paper[:2]):
        for sc in ("with_v_m", "without_v_m"):
            base = {
                "row": r,
                "scenario": sc,
                "sigma1": p["sigma1"],
                "sigma2": p["sigma2"],
                "eps1": p["eps1"],
                "eps2": p["eps2"],
                "a1": p["a1"],
                "a2": p["a2"],
                "ell1": p["ell1"],
                "ell2": p["ell2"],
                "runs": 4,
                "completed": 4,
                "transmissions_std": 10.0,
                "error_mean": 1.0,
                "error_std": 0.5,
            }
            mean = p[f"transmissions_{sc}"] + (0.0 if r == 0 else 100.0)
            aggregate.append(base | {"transmissions_mean": mean})
    result = SweepResult(
        spec=parse_spec(spec.raw), out=None, runs=[], aggregate=aggregate, computed=0, reused=0, failures=[]
    )
    lines = compare(result)
    assert set(COLUMNS) <= set(lines[0])
    assert lines[0]["transmissions_z"] == 0 and lines[0]["within_uncertainty"] is True
    se = 10.0 * (1 / 4 + 1 / 100) ** 0.5
    assert lines[2]["transmissions_se"] == pytest.approx(se)
    assert (
        lines[2]["transmissions_z"] == pytest.approx(100.0 / se) and lines[2]["within_uncertainty"] is False
    )
    text = markdown(lines, result)
    assert "Transmission cells outside the uncertainty: 2 of 4." in text


@pytest.mark.slow
def test_reproduce_table1_command(tmp_path, capsys):
    code = main(
        ["reproduce", "table1", "--runs", "1", "--out", str(tmp_path), "--workers", "2", "--no-progress"]
    )
    assert code == 0
    header = (tmp_path / "table1.csv").read_text().splitlines()[0]
    assert header.startswith(
        "sigma1,sigma2,eps1,eps2,a1,a2,ell1,ell2,scenario,transmissions_mean,"
        "transmissions_std,error_mean,error_std,paper_transmissions,paper_error,runs"
    )
    assert len((tmp_path / "table1.csv").read_text().splitlines()) == 27
    import pandas as pd

    for name in ("table1", "runs", "aggregate"):  # each CSV has its typed Parquet twin
        csv, parquet = pd.read_csv(tmp_path / f"{name}.csv"), pd.read_parquet(tmp_path / f"{name}.parquet")
        pd.testing.assert_frame_equal(parquet, csv, check_dtype=True)
    assert "transmissions_node1_mean" in pd.read_parquet(tmp_path / "aggregate.parquet")  # the arm's 2 nodes
    assert "# Table 1 of the paper, reproduced" in (tmp_path / "table1.md").read_text()
    resolved = json.loads((tmp_path / "spec.json").read_text())["resolved"]
    assert resolved["backend"] == "auto"  # simulate picks the engine for the robot arm
