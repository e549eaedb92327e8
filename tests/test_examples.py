"""The notebook-style example in examples/ runs as written, is short, and says what it shows."""

import runpy
from pathlib import Path

import pytest

EXAMPLE = Path(__file__).parents[1] / "examples" / "first_hour.py"


def test_first_hour_goes_from_model_to_table_to_plot_in_under_30_lines(tmp_path, monkeypatch, capsys):
    pytest.importorskip("matplotlib")
    lines = EXAMPLE.read_text().splitlines()
    assert len(lines) < 30  # the bound for "model to pandas table to plot"
    monkeypatch.chdir(tmp_path)
    runpy.run_path(str(EXAMPLE), run_name="__main__")
    out = capsys.readouterr().out
    assert "8 completed" in out  # the short repr: eight runs, all completed
    assert "transmissions_node0" in out and "transmissions_node1" in out  # the summary table
    png = tmp_path / "first_hour.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
