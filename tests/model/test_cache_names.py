"""Code from the disk cache never links another function's machine code (issue 23, found at its end).

numba names a compiled function's symbol by module, qualified name, argument types and a
per-process counter. A lambda compiled and cached in one process and a different lambda
with the same argument types compiled in the next could get the same symbol, and the
estimation model linked the wrong one: after editing ``h = lambda x: x.copy()`` into
``h = lambda x: 0.0 * x`` and running again on the same cache, the plant's ``lambda s: s *
s`` ran as ``0.0 * x``, so ``x' = x**2`` stayed at ``x = 1``. Each run is its own process
on one shared cache, as a user editing a script would run it.
"""

import json
import os
import subprocess
import sys
import textwrap

import pytest

SCRIPT = """
    import json
    import numpy as np
    from etobs import EstimationProblem, Node, Observer, Plant, Quadratic, SaveAt, simulate
    from etobs.model import StaticRule

    def run():
        esc = lambda s: s * s  # noqa: E731
        fp = esc
        plant = Plant(f_p=lambda t, x, u, v: fp(x), h=H, n_x=1, n_y=1)
        observer = Observer(f_o=lambda t, z, u, ybar, yhat: -z, n_z=1)
        node = Node((0,), StaticRule(gamma=Quadratic(1.0), eps=1.0))
        pb = EstimationProblem(plant, observer, [node])
        r = simulate(pb, [1.0], 0.9, z0=[1.0], backend="engine", save=SaveAt(grid=[0.0, 0.9]))
        print(json.dumps({"status": r.status_labels()[0], "x": float(r.on_grid().x[0, -1, 0])}))

    run()
"""


def _run(h: str, cache: str) -> dict:
    text = textwrap.dedent(SCRIPT).replace("h=H", f"h={h}")
    out = subprocess.run(
        [sys.executable, "-c", text],
        capture_output=True,
        text=True,
        timeout=600,
        env=dict(os.environ, ETOBS_CACHE_DIR=cache),
    )
    assert out.returncode == 0, out.stderr[-2000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.mark.parametrize("first, second", [("lambda x: x.copy()", "lambda x: 0.0 * x")])
def test_an_edited_lambda_run_again_on_the_same_cache_runs_its_own_code(first, second):
    cache = os.environ["ETOBS_CACHE_DIR"]  # the session's: its kernel is compiled once
    exact = 1.0 / (1.0 - 0.9)  # x' = x**2, x(0) = 1: x(t) = 1 / (1 - t)
    for h in (first, second):  # the second process loads the plant's lambdas from the cache
        got = _run(h, cache)
        assert got["status"] == "completed"
        assert got["x"] == pytest.approx(exact, rel=1e-7), h
