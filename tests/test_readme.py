"""The README's Python example runs as written."""

from pathlib import Path

from tests.docs_blocks import run_python_blocks


def test_readme_example_runs(capsys):
    run_python_blocks(Path(__file__).parents[1] / "README.md")
    assert "completed" in capsys.readouterr().out
