"""Cache files carry a SHA-256 checked before numba reads them (issue 23, section 2).

Random damage to a kernel's machine code crashed Python in LLVM (``BitcodeReader.cpp
... Assertion``) or was loaded silently; each load here runs in its own interpreter, so a
crash is a failed test, not a dead pytest. Every test has its own ``ETOBS_CACHE_DIR``.
"""

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import numpy as np
import pytest

from etobs.compile.cache import MAGIC

HEADER = len(MAGIC) + 32

LOAD = """
    import json, sys, warnings
    from pathlib import Path
    import numpy as np
    from etobs.compile import FunctionSpec, compile_function
    from etobs.hybrid import _jitcache

    with warnings.catch_warnings(record=True) as seen:
        warnings.simplefilter("always")
        tpl = Path(sys.argv[1])
        tpl.write_text("@jit\\ndef twice(x):\\n    return K7 * x + V[0]\\n")
        ns = _jitcache.build("crash", tpl, lambda: {"K7": 2.0, "V": np.array([0.5])}, {"jit": {}})
        kernel = ns["twice"](3.0)
        scale = 1.0001234
        cf = compile_function(lambda x: np.sin(x) * scale, FunctionSpec("A0", (2,), 2), "h")
    print(json.dumps({"r": [kernel, bool(cf.address)], "w": [str(w.message) for w in seen]}))
"""


def _load(cache: Path) -> dict:
    env = dict(os.environ, ETOBS_CACHE_DIR=str(cache))
    out = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(LOAD), str(cache.parent / "tpl.py")],
        capture_output=True,
        text=True,
        timeout=300,
        env=env,
    )
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])  # a crash: rc -6 (SIGABRT)
    return json.loads(out.stdout.strip().splitlines()[-1])


@pytest.fixture(scope="module")
def pristine(tmp_path_factory):
    cache = tmp_path_factory.mktemp("pristine") / "cache"
    first = _load(cache)
    assert first == {"r": [6.5, True], "w": []}
    return cache


def _files(cache: Path) -> list[Path]:
    return sorted(p for p in cache.rglob("*") if p.suffix in (".nbi", ".nbc"))


def _damaged(pristine: Path, tmp_path: Path, name: str, edit) -> Path:
    cache = tmp_path / "cache"
    shutil.copytree(pristine, cache)
    (path,) = [p for p in _files(cache) if p.name == name]
    stat = path.stat()
    path.write_bytes(edit(path.read_bytes()))
    os.utime(path, ns=(stat.st_atime_ns, stat.st_mtime_ns))  # numba's stamp unchanged: only bytes differ
    return cache


def test_every_file_is_written_with_its_checksum(pristine):
    names = [p.name for p in _files(pristine)]
    assert {Path(n).suffix for n in names} == {".nbi", ".nbc"}
    assert any("twice" in n for n in names) and any("functions" in str(p) for p in _files(pristine))
    for path in _files(pristine):
        assert path.read_bytes().startswith(MAGIC), path.name


# 3769 and 6737 (of numba's bytes of the kernel's .nbc) loaded silently before; 4611, 4816,
# 5414 and 5544 gave "LLVM bitcode parsing error"; the rest are seeded
FIXED = (3769, 6737, 4816)


@pytest.mark.parametrize("which", range(4))
def test_damage_anywhere_in_any_file_is_one_warning_then_a_clean_run(pristine, tmp_path, which):
    files = _files(pristine)
    path = files[which % len(files)]
    size = path.stat().st_size - HEADER
    rng = np.random.default_rng([23, which])
    positions = [p for p in FIXED if p < size - 16 and path.suffix == ".nbc"] + list(
        rng.integers(0, size - 16, 2)
    )
    for k, pos in enumerate(positions):
        noise = rng.integers(1, 256, 16, dtype=np.uint8).tobytes()

        def edit(raw, pos=HEADER + int(pos), noise=noise):
            block = bytes(a ^ b for a, b in zip(raw[pos : pos + 16], noise, strict=True))
            return raw[:pos] + block + raw[pos + 16 :]

        cache = _damaged(pristine, tmp_path / f"{k}", path.name, edit)
        once = _load(cache)
        assert once["r"] == [6.5, True]
        assert len(once["w"]) == 1, (path.name, pos, once["w"])
        assert "does not match its SHA-256: damaged; discarded it and compiled it again" in once["w"][0]
        assert _load(cache) == {"r": [6.5, True], "w": []}


def test_a_cache_from_before_checksums_is_discarded_once_with_a_warning(pristine, tmp_path):
    nbc = next(p for p in _files(pristine) if "twice" in p.name and p.suffix == ".nbc")
    cache = _damaged(pristine, tmp_path, nbc.name, lambda raw: raw[HEADER:])  # numba's bytes alone
    once = _load(cache)
    assert once["r"] == [6.5, True]
    assert len(once["w"]) == 1 and "without a checksum (written before etobs checked them" in once["w"][0]
    assert _load(cache) == {"r": [6.5, True], "w": []}
