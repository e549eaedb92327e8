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
structure or another key is moved to ``set-aside/`` with a warning and its runs are
computed again.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from etobs.errors import InputError

try:
    import fcntl
except ImportError:  # not POSIX (Windows): the folder is not locked, and lock() says so
    fcntl = None  # type: ignore[assignment]
from etobs.experiments.common import Experiment


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=repr)


def task_key(spec: Experiment, group: int) -> str:
    """Hash of everything that determines the numbers of one group."""
    ident = {"spec": spec.identity(), "kwargs": spec.group_identity(group)}
    return hashlib.sha256(_canonical(ident).encode()).hexdigest()[:20]


def _digest(body: dict[str, Any]) -> str:
    return hashlib.sha256(_canonical(body).encode()).hexdigest()


def _chunk_problem(data: Any, key: str) -> str:
    """What is wrong with a stored chunk, or ``""``."""
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


class ResultStore:
    """Chunk files of one output folder."""

    def __init__(self, out: str | Path) -> None:
        self.out = Path(out)
        self.chunks = self.out / "chunks"
        self.chunks.mkdir(parents=True, exist_ok=True)

    def _name(self, key: str, runs: tuple[int, ...]) -> str:
        return f"{key}__{runs[0]:06d}-{runs[-1]:06d}"

    def write(self, key: str, runs: tuple[int, ...], records: list[dict[str, Any]]) -> None:
        """Persist a finished chunk (and forget an earlier failure of the same runs).

        The file carries the SHA-256 of its key and records, checked when it is read.
        """
        name = self._name(key, runs)
        body = {"key": key, "records": records}
        atomic_write(self.chunks / f"{name}.json", _canonical({**body, "sha256": _digest(body)}))
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
        fh = open(path, "a+")
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
        payload = {"key": key, "runs": list(runs), "error": error, "where": where}
        for path in self.chunks.glob(f"{key}__*.error.json"):  # superseded by this failure
            try:
                if set(json.loads(path.read_text())["runs"]) <= set(runs):
                    path.unlink(missing_ok=True)
            except (OSError, json.JSONDecodeError, KeyError):
                continue
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
        """The chunk at ``path`` if it is whole and its own, else ``None`` (set aside, with a warning)."""
        try:
            data = json.loads(path.read_text())
        except FileNotFoundError:
            return None
        except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
            why = f"unreadable ({exc})"
        else:
            why = _chunk_problem(data, key)
            if not why:
                return data
        aside = self.out / "set-aside"
        aside.mkdir(exist_ok=True)
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
            try:
                err = json.loads(path.read_text())
                ok = isinstance(err, dict) and all(isinstance(r, int) for r in err["runs"])
            except (OSError, UnicodeDecodeError, json.JSONDecodeError, KeyError, TypeError):
                ok = False
            if not ok:  # not an error record of ours: its runs are simply retried
                path.unlink(missing_ok=True)
                continue
            if set(err["runs"]) <= present:
                path.unlink(missing_ok=True)
            elif any(r < runs and r not in present for r in err["runs"]):
                out.append(err)
        return out

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
