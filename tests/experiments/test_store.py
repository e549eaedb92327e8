"""The files of a sweep's folder that the store opens (issue 23, section 5).

Before: ``OUT/.lock`` as a symbolic link had its target truncated and the PID written
into it; a chunk that was a FIFO hung every resume, one that was a link to ``/dev/zero``
read until memory ran out, a 3 GiB sparse file was read whole and deeply nested JSON
ended in a RecursionError; a chunk whose records were edited and its SHA-256 recomputed
was reused, an unknown status included. Now: nothing is opened through a link or in a
way that blocks, reading is bounded in size (:func:`chunk_limit`) and depth, records are
validated, and what is refused is set aside with a warning and computed again.
"""

import json
import os
import shutil

import pytest

from etobs.errors import InputError
from etobs.experiments import parse_spec, run_sweep
from etobs.experiments.store import (
    CHUNK_DEPTH,
    NotRegular,
    ResultStore,
    _canonical,
    _digest,
    _load,
    chunk_limit,
    read_regular,
)

from .conftest import raw_spec

SPEC = raw_spec(
    rows=[{"k": 1.0}],
    scenarios=[{"name": "only"}],
    initial_states={"low": [-1.0], "high": [1.0], "runs": 4, "seed": 7},
    execution={"chunk_size": 2},
)


@pytest.fixture(scope="module")
def done(tmp_path_factory):
    """A finished sweep of 4 runs in 2 chunks; each test works on its own copy."""
    out = tmp_path_factory.mktemp("done") / "out"
    run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)
    return out


@pytest.fixture
def out(done, tmp_path):
    copy = tmp_path / "out"
    shutil.copytree(done, copy, symlinks=True)
    return copy


def chunk(out, k=0):
    return sorted(p for p in (out / "chunks").glob("*__*.json") if not p.name.endswith(".error.json"))[k]


def resume(out, why):
    """Resume the sweep: the damaged chunk is set aside with ``why`` and its 2 runs computed again."""
    before = (out / "runs.csv").read_text()
    with pytest.warns(RuntimeWarning, match=why) as seen:
        again = run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)
    assert len(seen) == 1
    assert (again.computed, again.reused) == (2, 2) and again.complete
    assert (out / "runs.csv").read_text() == before
    return again


def test_a_lock_that_is_a_symbolic_link_is_not_followed(out, tmp_path):
    victim = tmp_path / "victim.txt"
    victim.write_text("precious\n")
    (out / ".lock").unlink()
    (out / ".lock").symlink_to(victim)
    with pytest.raises(
        InputError, match=r"\.lock' is a symbolic link \(to '.*victim.txt'\); etobs does not follow"
    ):
        run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)
    assert victim.read_text() == "precious\n"  # was: the sweep's PID


def test_a_lock_that_is_a_fifo_is_refused_without_waiting(out):
    (out / ".lock").unlink()
    os.mkfifo(out / ".lock")
    with pytest.raises(InputError, match=r"\.lock' is a FIFO, not the regular file of the folder's lock"):
        run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)


def test_a_chunks_folder_that_is_a_symbolic_link_is_refused(out, tmp_path):
    shutil.move(out / "chunks", tmp_path / "elsewhere")
    (out / "chunks").symlink_to(tmp_path / "elsewhere")
    with pytest.raises(InputError, match=r"chunks' is a symbolic link; etobs does not follow it"):
        run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)


def _fifo(path):
    path.unlink()
    os.mkfifo(path)  # was: every resume hung in open()


def _dev_zero(path):
    path.unlink()
    path.symlink_to("/dev/zero")  # was: read until memory ran out


def _sparse(path):
    with open(path, "r+b") as fh:
        fh.truncate(3 << 30)  # 3 GiB of zeros on disk in a few blocks; was: read whole


def _nested(path):
    path.write_text("[" * 100_000 + "]" * 100_000)  # was: RecursionError on every resume


@pytest.mark.parametrize(
    ("damage", "why"),
    [
        (_fifo, r"was not a regular file \(a FIFO\)"),
        (_dev_zero, r"was a symbolic link \(to '/dev/zero'\), not a regular file"),
        (_sparse, r"was larger than the 2101248 bytes allowed \(3221225472 bytes\)"),
        (_nested, r"was nested deeper than the 4 levels of a chunk"),
    ],
    ids=["fifo", "link to /dev/zero", "3 GiB sparse", "nested 100000 deep"],
)
def test_a_chunk_that_cannot_be_read_safely_is_set_aside_and_recomputed(out, damage, why):
    target = chunk(out)
    damage(target)
    resume(out, why)
    aside = out / "set-aside" / target.name
    assert os.path.lexists(aside) and not os.path.lexists(target.with_suffix(".json.1"))


def _edited(out, edit):
    """Edit the first chunk's records and recompute its checksum, as someone who can write the folder can."""
    target = chunk(out)
    data = json.loads(target.read_text())
    edit(data["records"])
    body = {"key": data["key"], "records": data["records"]}
    target.write_text(_canonical({**body, "sha256": _digest(body)}))


def _set(k, v, i=0):
    def edit(recs):
        recs[i][k] = v

    return edit


@pytest.mark.parametrize(
    ("edit", "why"),
    [
        (_set("status", "totally_fine"), r"run 0: unknown status 'totally_fine'"),
        (_set("status", "running"), r"run 0: unknown status 'running'"),
        (_set("error", -5.0), r"run 0: `error` is not of its type or out of its range"),
        (_set("error", "small"), r"run 0: `error` is not of its type"),
        (_set("transmissions", [-1]), r"run 0: `transmissions` is not of its type"),
        (_set("transmissions", [True]), r"run 0: `transmissions` is not of its type"),
        (_set("min_inter_event_time", [0.1, 0.2]), r"run 0: `min_inter_event_time` is not of its type"),
        (_set("x0", [float("nan")]), r"run 0: `x0` is not of its type"),
        (_set("steps", 1.5), r"run 0: `steps` is not of its type"),
        (_set("backend", "gpu"), r"run 0: unknown backend 'gpu'"),
        (_set("run", 7), r"a record of run 7, outside the chunk's runs 0..1"),
        (_set("run", 0, i=1), r"a run is stored twice"),
        (lambda recs: recs.pop(), r"its runs are not those of its name, 0..1"),
        (lambda recs: recs[0].pop("seconds"), r"a record without the keys of this version"),
        (lambda recs: recs[0].update(extra=1), r"a record without the keys of this version"),
    ],
    ids=lambda v: v if isinstance(v, str) else "",
)
def test_edited_records_with_a_recomputed_checksum_are_set_aside(out, edit, why):
    _edited(out, edit)
    resume(out, r"was not a chunk etobs writes \(" + why)


def test_records_at_the_edge_of_their_ranges_are_kept(out):
    def edge(recs):
        recs[0].update(error=0.0, steps=0, transmissions=[0], min_inter_event_time=[None], seconds=0.0)
        recs[1].update(error=None, status="max_jumps")

    _edited(out, edge)
    again = run_sweep(parse_spec(SPEC), out, executor="serial", progress=False)
    assert (again.computed, again.reused) == (0, 4)
    assert sorted((r["run"], r["status"]) for r in again.runs)[:2] == [(0, "completed"), (1, "max_jumps")]


@pytest.mark.parametrize("runs", [1, 20])
def test_a_chunk_is_read_up_to_its_limit_and_not_one_byte_more(tmp_path, runs):
    limit = chunk_limit(runs)
    assert limit == 4096 + runs * (1 << 20)
    path = tmp_path / "c.json"
    path.write_bytes(b" " * (limit - 2) + b"[]")
    assert _load(path, limit, CHUNK_DEPTH) == []
    path.write_bytes(b" " * (limit - 1) + b"[]")
    with pytest.raises(NotRegular, match=rf"larger than the {limit} bytes allowed \({limit + 1} bytes\)"):
        read_regular(path, limit)


def test_a_chunk_is_parsed_up_to_its_depth_and_not_one_level_more(tmp_path):
    path = tmp_path / "c.json"
    path.write_text('{"a": [{"b": [1, "]]]]"]}]}')  # depth 4; brackets in strings do not count
    assert _load(path, 1000, CHUNK_DEPTH) == {"a": [{"b": [1, "]]]]"]}]}
    path.write_text('{"a": [{"b": [[1]]}]}')
    with pytest.raises(NotRegular, match=r"nested deeper than the 4 levels of a chunk"):
        _load(path, 1000, CHUNK_DEPTH)


def test_an_error_file_that_is_a_fifo_does_not_hang_and_is_removed(out):
    key = chunk(out).name.partition("__")[0]
    bad = out / "chunks" / f"{key}__000000-000001.error.json"
    os.mkfifo(bad)
    store = ResultStore(out)
    assert store.errors(key, set(), 4) == []
    assert not os.path.lexists(bad)
