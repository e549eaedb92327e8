import json

import pytest

from etobs.cli.main import main


def test_demo_writes_figures_and_summary(tmp_path, capsys):
    out = tmp_path / "ra"
    code = main(["demo", "robot-arm", "--out", str(out), "--t-end", "3", "--window", "1,3"])
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    for key in ("transmissions", "min_inter_event_time", "max_error_window", "status", "t_end", "x0"):
        assert key in summary
    assert summary["status"] == "completed"
    assert summary["t_end"] == 3.0 and summary["x0"] == [3.0, 2.0, 3.0, -2.0]
    assert len(summary["transmissions"]) == 2 and sum(summary["transmissions"]) > 0
    assert summary["max_error_window"] > 0
    for name in ("states.png", "error.png", "inter_event_times.png"):
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    printed = capsys.readouterr().out
    assert "min inter-event time" in printed and "paper" in printed


def test_demo_options(tmp_path):
    out = tmp_path / "ra"
    code = main(
        [
            "demo",
            "robot-arm",
            "--out",
            str(out),
            "--t-end",
            "1",
            "--x0",
            "1,0,1,0",
            "--no-noise",
            "--no-disturbance",
            "--no-plots",
        ]
    )
    assert code == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["x0"] == [1.0, 0.0, 1.0, 0.0]
    assert summary["noise"] is False and summary["disturbance"] is False
    assert summary["max_error_window"] is None  # the window [20, 30] lies past t_end
    assert not (out / "states.png").exists()


@pytest.mark.parametrize(("asked", "ran"), [("auto", "engine"), ("numba", "engine"), ("scipy", "scipy")])
def test_demo_backends_and_their_earlier_names(tmp_path, capsys, asked, ran):
    out = tmp_path / "ra"
    argv = ["demo", "robot-arm", "--out", str(out), "--t-end", "0.5", "--no-plots", "--backend", asked]
    assert main(argv) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["backend"] == ran and summary["backend_reason"]
    assert f"({ran} backend)" in capsys.readouterr().out


def test_demo_backend_help_names_the_backends(capsys):
    with pytest.raises(SystemExit):
        main(["demo", "robot-arm", "--help"])
    text = " ".join(capsys.readouterr().out.split())
    assert "auto (the compiled engine; the scipy reference for a rule of your own)" in text
    assert "numba is an earlier name of engine" in text


def test_demo_names_the_retired_numpy_backend(capsys):
    with pytest.raises(SystemExit):
        main(["demo", "robot-arm", "--backend", "numpy"])
    assert "--backend` 'numpy' (the batched numpy solver) was retired" in capsys.readouterr().err


@pytest.mark.parametrize(
    ("argv", "match"),
    [
        (["--x0", "3,2"], r"--x0 must be 4 comma-separated finite numbers \(e.g. 3,2,3,-2\); got '3,2'"),
        (["--x0", "3,2,nan,1"], r"--x0 must be 4 comma-separated finite numbers"),
        (["--window", "20"], r"--window must be 2 comma-separated finite numbers"),
        (["--t-end", "-1"], r"argument --t-end: must be a finite number > 0; got '-1'"),
        (["--t-end", "nan"], r"argument --t-end: must be a finite number > 0; got 'nan'"),
        (["--rtol", "1e400"], r"argument --rtol: must be a finite number > 0; got '1e400'"),
        # a ValueError traceback from numpy, and 1e4 < --t-end < 1e300 filled the memory with the error grid
        (
            ["--t-end", "1e308"],
            r"--t-end 1e\+308 s is too long for the 0.001-s error grid \(at most 1e\+07 points\)",
        ),
        (["--t-end", "1e5"], r"--t-end 100000 s is too long .*: use --t-end <= 10000"),
        # a reversed window printed 'max |x - xhat| on [30, 20]: n/a' and exit 0
        (["--window", "30,20"], r"--window 30,20: its start lies after its end"),
        (
            ["--backend", "rk4"],
            r"argument --backend: `--backend` must be one of \('auto', 'engine', 'scipy'\)",
        ),
    ],
)
def test_demo_bad_arguments(argv, match, capsys, tmp_path):
    with pytest.raises(SystemExit) as info:
        main(["demo", "robot-arm", "--out", str(tmp_path), *argv])
    err = capsys.readouterr().err + str(info.value.code)
    assert info.value.code == 2
    import re

    assert re.search(match, err), err
