"""docs/plots.md's example runs as written and draws what the page says."""

import re
from pathlib import Path

import numpy as np
import pytest

DOC = Path(__file__).parents[2] / "docs" / "plots.md"


@pytest.mark.slow  # compiles the example's model (a minute on a busy machine)
def test_the_example_runs_and_writes_both_images(tmp_path, monkeypatch):
    (code,) = [b for b in re.findall(r"```python\n(.*?)```", DOC.read_text(), re.S) if "hybrid-arc.png" in b]
    monkeypatch.chdir(tmp_path)
    scope = {}
    exec(compile(code, str(DOC), "exec"), scope)
    for name in ("hybrid-arc.png", "held-outputs.png"):
        assert (tmp_path / name).stat().st_size > 10_000
        # the page shows the images this block writes
        assert f"(img/{name})" in DOC.read_text()
    result, ax = scope["result"], scope["ax"]
    assert result.ok
    # "each node's transmission resets its own e_i to 0 and leaves the other's unchanged"
    log = result.transmissions.select(run=0)
    arc = result.arc(0)
    before = np.searchsorted(arc.j, log.j, side="right") - 1
    own = arc.e[before + 1, log.rule]
    other = arc.e[before + 1, 1 - log.rule]
    np.testing.assert_array_equal(own, 0.0)
    np.testing.assert_array_equal(other, arc.e[before, 1 - log.rule])
    assert "flows refined with the save grid" in ax.figure._suptitle.get_text()
    assert "from the hybrid arc" in scope["axes"][0].get_title()
