"""docs/design.md's end-to-end example runs as written, and `etobs check` on its spec agrees."""

import json
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("cvxpy")

from etobs.cli.main import main
from etobs.estimation import min_inter_event_time
from tests.docs_blocks import run_page_in

PAGE = Path(__file__).parents[1] / "docs" / "design.md"


def test_design_page_runs_from_matrices_to_a_checked_certificate_and_a_simulation(
    tmp_path, monkeypatch, capsys
):
    ns = run_page_in(PAGE, tmp_path, monkeypatch, ("chain",))  # the page imports the chain.py it saves
    out = capsys.readouterr().out
    cert, result = ns["cert"], ns["result"]
    assert cert.ok and "certificate: all conditions hold" in out
    assert "P designed together with L by observer_gain (objective 'max_decay')" in out
    assert cert.mu == pytest.approx(0.5) and cert.scale == pytest.approx(1.0)
    assert result.status_labels() == ["completed", "completed"]
    # the figures the page shows (SDP solvers differ in the last digits: compared to 0.1 %, counts to 3 %)
    assert cert.error_bound == pytest.approx(0.727516, rel=1e-3)
    assert [nd.tau for nd in cert.nodes] == pytest.approx([0.01446, 0.02846], rel=1e-3)
    counts = json.loads(out.split("transmissions per run and node: ")[1].splitlines()[0])
    assert np.array(counts) == pytest.approx(np.array([[567, 257], [435, 200]]), rel=0.03)
    assert (
        repr(cert).splitlines()[1]
        == "  nu = 0.1015, a_U = 0.203, mu = 0.5, error bound = 0.7275, min tau [s] = 0.01446"
    )
    # Theorem 4 on the page's runs (E was estimated on them, plus 20 %)
    assert np.all(min_inter_event_time(result) >= np.array([nd.tau for nd in cert.nodes]))
    # etobs check on the spec the page wrote: certify's certificate, number for number
    assert main(["check", "chain.toml", "--json"]) == 0
    cli, py = json.loads(capsys.readouterr().out), cert.to_dict()
    assert cli["iss"].pop("P_origin") == "given with L (re-checked with eigenvalues)"
    assert py["iss"].pop("P_origin").startswith("designed together with L")
    assert cli == py
    # without P, check_gain's P: another bound (the page says 0.802), and the report says why
    spec = Path("chain.toml")
    spec.write_text("\n".join(line for line in spec.read_text().splitlines() if not line.startswith("P = ")))
    assert main(["check", "chain.toml"]) == 0
    text = capsys.readouterr().out
    assert float(text.split("ultimate bound on |x - xhat|: ")[1].split()[0]) == pytest.approx(0.802, rel=2e-3)
    assert "note: no observer.P given" in text
