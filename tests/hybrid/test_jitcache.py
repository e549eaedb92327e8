"""The on-disk compile cache of the compiled backend (etobs.hybrid._jitcache)."""

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

numba = pytest.importorskip("numba")

from etobs.hybrid import _jitcache  # noqa: E402
from etobs.hybrid.compiled import CompiledSystem, solve_compiled  # noqa: E402

from .test_compiled import ball_flow, ball_jump  # noqa: E402

ROOT = Path(__file__).resolve().parents[2]


def test_cache_dir_from_environment(monkeypatch, tmp_path):
    monkeypatch.setenv("ETOBS_CACHE_DIR", str(tmp_path / "k"))
    assert _jitcache.cache_dir() == tmp_path / "k"
    for off in ("off", "0", "", "None"):
        monkeypatch.setenv("ETOBS_CACHE_DIR", off)
        assert _jitcache.cache_dir() is None
    monkeypatch.delenv("ETOBS_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "xdg"))
    assert _jitcache.cache_dir() == tmp_path / "xdg" / "etobs" / "kernels"
    monkeypatch.delenv("XDG_CACHE_HOME")
    assert _jitcache.cache_dir() == Path.home() / ".cache" / "etobs" / "kernels"


def test_reference_names_importable_functions_only():
    ref = _jitcache.reference(ball_flow)
    assert ref == "tests.hybrid.test_compiled:ball_flow"
    assert _jitcache.resolve(ref) is ball_flow

    @numba.njit
    def local(x):
        return x

    assert _jitcache.reference(local) is None  # a closure cannot be imported
    assert _jitcache.reference(lambda x: x) is None  # not compiled
    assert _jitcache.reference(np.sin) is None


def test_constants_are_written_exactly():
    values = {
        "A": np.array([[0.1, 1 / 3], [np.pi, -2.5e-300]]),
        "I": 7,
        "F": 1 / 7,
        "B": True,
        "INF": np.inf,
    }
    ns: dict = {}
    exec("import numpy\n" + "\n".join(f"{k} = {_jitcache._literal(k, v)}" for k, v in values.items()), ns)
    assert np.array_equal(ns["A"], values["A"]) and ns["A"].dtype == np.float64
    assert ns["I"] == 7 and ns["F"] == 1 / 7 and ns["B"] is True and ns["INF"] == np.inf
    with pytest.raises(
        TypeError, match="constant 'S' must be a bool, int, float or a float64 or int64 array; got str"
    ):
        _jitcache._literal("S", "text")


def _ball_script() -> str:
    return textwrap.dedent(
        """
        import json, numpy as np
        from etobs.hybrid import compiled as comp
        from tests.hybrid.test_compiled import BALL
        sol = comp.solve_compiled(BALL, [[1.0, 0.0], [2.0, 1.0]], (0.0, 3.0), params=[0.5])
        kernel = next(iter(comp._BUILT.values()))[0]
        print(json.dumps({"hits": sum(kernel.stats.cache_hits.values()),
                          "misses": sum(kernel.stats.cache_misses.values()),
                          "t": sol.jumps.t.tolist()}))
        """
    )


def test_second_process_loads_the_compiled_kernel_from_disk(tmp_path):
    import json

    env = {**os.environ, "ETOBS_CACHE_DIR": str(tmp_path), "PYTHONPATH": str(ROOT)}
    runs = []
    for _ in range(2):
        out = subprocess.run(
            [sys.executable, "-c", _ball_script()],
            env=env,
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=300,
        )
        assert out.returncode == 0, out.stderr
        runs.append(json.loads(out.stdout.strip().splitlines()[-1]))
    assert (runs[0]["hits"], runs[0]["misses"]) == (0, 1)  # compiled, then saved
    assert (runs[1]["hits"], runs[1]["misses"]) == (1, 0)  # loaded
    assert runs[0]["t"] == runs[1]["t"] and len(runs[0]["t"]) > 5
    generated = sorted(p.name for p in tmp_path.glob("*.py"))
    assert len(generated) == 1 and generated[0].startswith("kernel_dop853_")


def test_functions_that_cannot_be_imported_compile_in_memory(tmp_path, monkeypatch):
    monkeypatch.setenv("ETOBS_CACHE_DIR", str(tmp_path))

    @numba.njit
    def flow(t, x, p, args, work, dx):
        dx[0] = -x[0]

    @numba.njit
    def guard(t, x, p, args, work, g):
        g[0] = x[0] - 2.0

    system = CompiledSystem(n=1, n_rules=1, flow=flow, guard=guard, jump=ball_jump)
    sol = solve_compiled(system, [1.0], (0.0, 1.0))
    assert abs(sol.x_final[0, 0] - np.exp(-1.0)) < 1e-9
    assert list(tmp_path.iterdir()) == []  # nothing written


def test_unusable_cache_folder_warns_and_compiles_in_memory(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("ETOBS_CACHE_DIR", str(blocker / "kernels"))
    monkeypatch.setattr(_jitcache, "_WARNED", [])
    template = tmp_path / "tpl.py"
    template.write_text("@jit\ndef twice(x):\n    return K * FN(x)\n")
    with pytest.warns(RuntimeWarning, match="cannot use the compile cache in .*kernels.*compiling in memory"):
        ns = _jitcache.build("t", template, {"K": 2.0}, {"FN": ball_identity}, {"jit": {}})
    assert ns["twice"](3.0) == 6.0


@numba.njit
def ball_identity(x):
    return x
