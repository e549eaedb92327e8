"""docs/design.md's end-to-end example runs as written, and `etobs check` on its spec agrees."""

import json
import sys
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cvxpy")

from etobs.cli.main import main
from etobs.estimation import min_inter_event_time
from tests.docs_blocks import run_python_blocks

PAGE = Path(__file__).parents[1] / "docs" / "design.md"


def test_design_page_runs_from_matrices_to_a_checked_certificate_and_a_simulation(
    tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.syspath_prepend(str(tmp_path))  # the page imports the chain.py it has the reader save
    try:
        ns = run_python_blocks(PAGE, tmp_path)
    finally:
        sys.modules.pop("chain", None)
    out = capsys.readouterr().out
    cert, result = ns["cert"], ns["result"]
    assert cert.ok and "certificate: all conditions hold" in out
    assert "P designed together with L by observer_gain (objective 'max_decay')" in out
    assert cert.mu == pytest.approx(0.5) and cert.scale == pytest.approx(1.0)
    assert result.status_labels() == ["completed", "completed"]
    assert "transmissions per run and node: [[" in out
    # Theorem 4 on the page's runs (E was estimated on them, plus 20 %)
    assert np.all(min_inter_event_time(result) >= np.array([nd.tau for nd in cert.nodes]))
    # etobs check on the spec the page wrote: certify's certificate, number for number
    assert main(["check", "chain.toml", "--json"]) == 0
    cli, py = json.loads(capsys.readouterr().out), cert.to_dict()
    assert cli["iss"].pop("P_origin") == "given with L (re-checked with eigenvalues)"
    assert py["iss"].pop("P_origin").startswith("designed together with L")
    assert cli == py
