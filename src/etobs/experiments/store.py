"""Persistence of a sweep: every finished chunk is written atomically under its key.

Layout of an output folder::

    spec.json          the spec as given and resolved (defaults filled in)
    meta.json          seed, package versions, start and end times
    chunks/KEY__A-B.json        records of runs A..B of one group (a sweep's row under a
                                scenario, a comparison's rule on a network)
    chunks/KEY__A-B.error.json  the error of a chunk that failed
    set-aside/         chunks found damaged, changed or foreign (a warning says so)
    .lock              held by the one process writing to the folder

``KEY`` is a hash of the spec's identity and the group's, so results of a changed spec
are never mixed with old ones, and a rerun finds what is already done. A chunk file
carries the SHA-256 of its key and records; one that does not match, has another
structure or another key, holds a record that is not one :func:`run_task` writes
(:func:`~etobs.experiments.runner.record_problem`), is not a regular file (a symbolic
link, a FIFO, a device), is larger than :func:`chunk_limit` allows or nested deeper than
:data:`CHUNK_DEPTH` is moved to ``set-aside/`` with a warning and its runs are computed
again. The checksum catches damage (a torn or truncated write, a flipped byte), not
edits: whoever can write the folder can recompute it. No file of the folder is opened
through a symbolic link, and none is opened in a way that blocks (a FIFO).
"""

from __future__ import annotations

import errno
import hashlib
import json
import os
import re
import stat
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

import numpy as np

from etobs.errors import InputError

try:
    import fcntl
except ImportError:  # not POSIX (Windows): the folder is not locked, and lock() says so
    fcntl = None  # type: ignore[assignment]
from etobs.experiments.common import Experiment
from etobs.experiments.runner import record_problem

#: Most bytes of one run's record in a chunk file. A record holds a few numbers per node
#: and per plant state (about 60 kB with 1,000 nodes and 1,000 states), so this leaves
#: room for 10x more; a chunk is read only up to :func:`chunk_limit` bytes (a 3 GiB sparse
#: file or ``/dev/zero`` under a chunk's name was read whole, or forever).
MAX_RECORD_BYTES = 1 << 20
#: Nesting of a chunk file: the chunk's object, its records' list, a record, a record's
#: list (``x0``). Anything deeper is not a chunk, and is not parsed (deeply nested JSON
#: ended every resume in a RecursionError).
CHUNK_DEPTH = 4
#: Most bytes of a failed chunk's error file; the error text is cut to its last
#: :data:`MAX_ERROR_CHARS` characters when written (the last line is the exception's).
MAX_ERROR_BYTES = 1 << 20
MAX_ERROR_CHARS = 1 << 18
#: A chunk file's name: its key and the first and last of its runs.
_CHUNK_NAME = re.compile(r"^(?P<key>[0-9a-f]+)__(?P<first>\d{6,})-(?P<last>\d{6,})\.json$")
#: Opening never follows a symbolic link nor waits for a FIFO's writer.
_OPEN_FLAGS = getattr(os, "O_NOFOLLOW", 0) | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)


def chunk_limit(runs: int) -> int:
    """Most bytes a chunk file of ``runs`` runs may have: 4 KiB plus :data:`MAX_RECORD_BYTES` a run."""
    return 4096 + runs * MAX_RECORD_BYTES


class NotRegular(OSError):
    """A file of the store that is a symbolic link, a FIFO, a device or a folder."""


def read_regular(path: Path, limit: int) -> str:
    """The text of ``path``, read without following a symbolic link or blocking, at most ``limit`` bytes.

    Raises
    ------
    NotRegular
        ``path`` is not a regular file, or it is larger than ``limit`` bytes.
    FileNotFoundError, OSError, UnicodeDecodeError
        As reading a file does.

    """
    try:
        fd = os.open(path, os.O_RDONLY | _OPEN_FLAGS)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise NotRegular(f"a symbolic link (to {os.readlink(path)!r}), not a regular file") from None
        raise
    with os.fdopen(fd, "rb") as fh:
        st = os.fstat(fd)
        if not stat.S_ISREG(st.st_mode):
            raise NotRegular(f"not a regular file ({_kind(st.st_mode)})")
        if st.st_size > limit:
            raise NotRegular(f"larger than the {limit} bytes allowed ({st.st_size} bytes)")
        data = fh.read(limit + 1)  # the file may grow after fstat
    if len(data) > limit:
        raise NotRegular(f"larger than the {limit} bytes allowed")
    return data.decode()


def _kind(mode: int) -> str:
    kinds = [(stat.S_ISFIFO, "a FIFO"), (stat.S_ISDIR, "a folder"), (stat.S_ISCHR, "a character device")]
    kinds += [(stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket")]
    return next((name for test, name in kinds if test(mode)), "not a file")


def json_depth(text: str) -> int:
    """How deeply the arrays and objects of the JSON ``text`` nest (strings are skipped)."""
    bare = re.sub(r'"(?:[^"\\]|\\.)*"', "", text)
    marks = np.frombuffer(re.sub(r"[^\[\]{}]", "", bare).encode(), dtype=np.uint8)
    if marks.size == 0:
        return 0
    steps = np.where((marks == ord("[")) | (marks == ord("{")), 1, -1)
    return int(np.cumsum(steps).max())


def _load(path: Path, limit: int, depth: int) -> Any:
    """The JSON of the regular file ``path``, at most ``limit`` bytes and ``depth`` levels deep."""
    text = read_regular(path, limit)
    if json_depth(text) > depth:
        raise NotRegular(f"nested deeper than the {depth} levels of a chunk")
    return json.loads(text)


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=repr)


def task_key(spec: Experiment, group: int) -> str:
    """Hash of everything that determines the numbers of one group."""
    ident = {"spec": spec.identity(), "kwargs": spec.group_identity(group)}
    return hashlib.sha256(_canonical(ident).encode()).hexdigest()[:20]


def _digest(body: dict[str, Any]) -> str:
    return hashlib.sha256(_canonical(body).encode()).hexdigest()


def _chunk_problem(data: Any, key: str, first: int, last: int) -> str:
    """What is wrong with a stored chunk of runs ``first .. last``, or ``""``."""
    if not isinstance(data, dict) or set(data) != {"key", "records", "sha256"}:
        return "not a chunk of this version (wrong structure)"
    if data["key"] != key:
        return f"stored under key {data['key']!r}, not its file's {key!r}"
    recs = data["records"]
    if not isinstance(recs, list) or not all(
        isinstance(r, dict) and isinstance(r.get("run"), int) for r in recs
    ):
        return "not a chunk of this version (wrong records)"
    if data["sha256"] != _digest({"key": data["key"], "records": recs}):
        return "changed since it was written (its checksum does not match)"
    # the checksum matches, but whoever wrote the folder may have recomputed it
    why = next((w for w in (record_problem(r, first, last) for r in recs) if w), "")
    if why:
        return f"not a chunk etobs writes ({why})"
    if len({r["run"] for r in recs}) != len(recs):
        return "not a chunk etobs writes (a run is stored twice)"
    if not recs or recs[0]["run"] != first or recs[-1]["run"] != last:
        return f"not a chunk etobs writes (its runs are not those of its name, {first}..{last})"
    return ""


def last_line(failure: dict[str, Any]) -> str:
    """The last line of a stored failure's error (the exception), for reports."""
    text = str(failure.get("error", "")).strip()
    if not text:
        return "unknown error"
    # an etobs error's message names the key and the value; its class path
    # (etobs._spec.SpecError) is internal, so only the message is shown
    return re.sub(r"^etobs(?:\.\w+)+: ", "", text.splitlines()[-1])


def atomic_write(path: Path, text: str | bytes) -> None:
    """Write ``text`` (or bytes) to ``path`` so that readers see the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "wb" if isinstance(text, bytes) else "w") as fh:
            fh.write(text)
            fh.flush()
            os.fsync(fh.fileno())
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _open_lock(path: Path) -> Any:
    """``path`` opened for reading and writing, created if missing; refused unless a regular file.

    A symbolic link is not followed: the lock's holder truncates it and writes its process
    id, which through a link went into the link's target.
    """
    try:
        fd = os.open(path, os.O_RDWR | os.O_CREAT | _OPEN_FLAGS, 0o644)
    except OSError as exc:
        if exc.errno != errno.ELOOP:
            raise
        raise InputError(
            f"{str(path)!r} is a symbolic link (to {os.readlink(path)!r}); etobs does not follow it "
            "(the lock would write into its target): remove it, or use another output folder"
        ) from None
    mode = os.fstat(fd).st_mode
    if not stat.S_ISREG(mode):
        os.close(fd)
        raise InputError(
            f"{str(path)!r} is {_kind(mode)}, not the regular file of the folder's lock: "
            "remove it, or use another output folder"
        )
    return os.fdopen(fd, "r+")


def _own_folder(path: Path) -> Path:
    """``path`` created as a folder; refused if it is a symbolic link or another kind of file."""
    if path.is_symlink():
        raise InputError(
            f"{str(path)!r} is a symbolic link; etobs does not follow it (chunks would be read and "
            "written elsewhere): remove it, or use another output folder"
        )
    path.mkdir(parents=True, exist_ok=True)
    return path


class ResultStore:
    """Chunk files of one output folder."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.out.mkdir(parents=True, exist_ok=True)
        self.chunks = _own_folder(self.out / "chunks")

    def _name(self, key: str, runs: tuple[int, ...]) -> str:
        return f"{key}__{runs[0]:06d}-{runs[-1]:06d}"

    def write(self, key: str, runs: tuple[int, ...], records: list[dict[str, Any]]) -> None:
        """Persist a finished chunk (and forget an earlier failure of the same runs).

        The file carries the SHA-256 of its key and records, checked when it is read.
        """
        name = self._name(key, runs)
        body = {"key": key, "records": records}
        text = _canonical({**body, "sha256": _digest(body)})
        limit = chunk_limit(runs[-1] - runs[0] + 1)
        if len(text) > limit:  # it would be set aside when read: refuse it now, not on every resume
            raise InputError(
                f"the records of runs {runs[0]}..{runs[-1]} take {len(text)} bytes, more than the {limit} "
                f"a chunk file may have ({MAX_RECORD_BYTES} bytes a run): report this as a bug"
            )
        atomic_write(self.chunks / f"{name}.json", text)
        (self.chunks / f"{name}.error.json").unlink(missing_ok=True)

    @contextmanager
    def lock(self) -> Iterator[None]:
        """Hold the folder for one writer; a second sweep or comparison on it is refused.

        Held, the folder's temporary files are this writer's own or a dead writer's, so
        they may be removed (:meth:`clean_temporary`).
        """
        path = self.out / ".lock"
        if fcntl is None:
            warnings.warn(
                f"no file locking on this platform: {str(self.out)!r} is not protected from a second "
                "writer; run one sweep or comparison per folder",
                RuntimeWarning,
                stacklevel=3,
            )
            yield
            return
        fh = _open_lock(path)
        try:
            try:
                fcntl.flock(fh.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                fh.seek(0)
                holder = fh.read().strip() or "unknown"
                raise InputError(
                    f"another sweep or comparison is writing to {str(self.out)!r} (process {holder} "
                    f"holds {str(path)!r}): wait for it to finish, or use another output folder"
                ) from None
            except OSError as exc:  # a file system without locks (some network mounts)
                raise InputError(
                    f"cannot lock {str(path)!r} ({exc}): use an output folder on a local disk"
                ) from exc
            fh.seek(0)
            fh.truncate()
            fh.write(str(os.getpid()))
            fh.flush()
            yield
        finally:
            fh.close()  # releases the lock

    def write_error(self, key: str, runs: tuple[int, ...], error: str, where: str = "") -> None:
        """Record a failed chunk with its error (``where``: its row and scenario, for reports)."""
        payload = {"key": key, "runs": list(runs), "error": error[-MAX_ERROR_CHARS:], "where": where}
        for path in self.chunks.glob(f"{key}__*.error.json"):  # superseded by this failure
            err = self._error(path)
            if err is None or set(err["runs"]) <= set(runs):
                path.unlink(missing_ok=True)
        atomic_write(self.chunks / f"{self._name(key, runs)}.error.json", _canonical(payload))

    def records(self, key: str, runs: int | None = None) -> dict[int, dict[str, Any]]:
        """Stored runs ``0 .. runs-1`` of ``key`` (all when ``runs`` is None), each once."""
        out: dict[int, dict[str, Any]] = {}
        for path in sorted(self.chunks.glob(f"{key}__*.json")):
            if path.name.endswith(".error.json"):
                continue
            data = self._checked(path, key)
            if data is None:
                continue  # set aside: the runs will be computed again
            for rec in data["records"]:
                if runs is None or int(rec["run"]) < runs:
                    out.setdefault(int(rec["run"]), rec)
        return out

    def _checked(self, path: Path, key: str) -> dict[str, Any] | None:
        """The chunk at ``path`` if it is whole and its own, else ``None`` (set aside, with a warning).

        It is read only if it is a regular file of at most :func:`chunk_limit` bytes for
        the runs its name gives, nested at most :data:`CHUNK_DEPTH` deep.
        """
        name = _CHUNK_NAME.match(path.name)
        if name is None:
            why = "not named as a chunk (KEY__FIRST-LAST.json)"
        else:
            first, last = int(name["first"]), int(name["last"])
            try:
                data = _load(path, chunk_limit(max(last - first + 1, 1)), CHUNK_DEPTH)
            except FileNotFoundError:
                return None
            except NotRegular as exc:
                why = str(exc)
            except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
                why = f"unreadable ({exc})"
            else:
                why = _chunk_problem(data, key, first, last)
                if not why:
                    return data
        aside = _own_folder(self.out / "set-aside")
        target, k = aside / path.name, 1
        while target.exists():  # keep every damaged copy
            target, k = aside / f"{path.name}.{k}", k + 1
        try:
            path.replace(target)
        except FileNotFoundError:
            return None
        warnings.warn(
            f"chunk {path.name} was {why}: moved to {str(aside)!r}; its runs are computed again",
            RuntimeWarning,
            stacklevel=3,
        )
        return None

    def errors(self, key: str, present: set[int], runs: int) -> list[dict[str, Any]]:
        """Failures of ``key`` still standing: some of their runs below ``runs`` are missing.

        Error files whose runs have all been stored since (in any chunking) are deleted.
        """
        out = []
        for path in sorted(self.chunks.glob(f"{key}__*.error.json")):
            err = self._error(path)
            if err is None:  # not an error record of ours: its runs are simply retried
                path.unlink(missing_ok=True)
                continue
            if set(err["runs"]) <= present:
                path.unlink(missing_ok=True)
            elif any(r < runs and r not in present for r in err["runs"]):
                out.append(err)
        return out

    @staticmethod
    def _error(path: Path) -> dict[str, Any] | None:
        """The failure stored at ``path``, or ``None`` if it is not one (the caller removes it)."""
        try:
            err = _load(path, MAX_ERROR_BYTES, 2)
        except (OSError, UnicodeDecodeError, json.JSONDecodeError):  # NotRegular included
            return None
        fields_ok = isinstance(err, dict) and isinstance(err.get("runs"), list)
        if not fields_ok or not all(isinstance(r, int) and not isinstance(r, bool) for r in err["runs"]):
            return None
        if not err["runs"] or not all(isinstance(err.get(k), str) for k in ("key", "error", "where")):
            return None
        return err

    def other_chunks(self, keys: set[str]) -> int:
        """Chunk files stored under none of ``keys``: another spec's or another version's.

        They are left in place (a changed spec may be changed back) but never read for
        ``keys``; reports count them, so a recomputation is not silent.
        """
        return sum(
            1
            for path in self.chunks.glob("*__*.json")
            if not path.name.endswith(".error.json") and path.name.partition("__")[0] not in keys
        )

    def clean_temporary(self) -> None:
        """Remove temporary files left by a writer that was killed mid-write (chunks and tables)."""
        for path in [*self.chunks.glob(".*.tmp"), *self.out.glob(".*.tmp")]:
            path.unlink(missing_ok=True)
