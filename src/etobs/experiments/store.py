"""Persistence of a sweep: every finished chunk is written atomically under its key.

Layout of an output folder::

    spec.json          the spec as given and resolved (defaults filled in)
    meta.json          seed, package versions, start and end times
    chunks/KEY__A-B.json        records of runs A..B of one group (a sweep's row under a
                                scenario, a comparison's rule on a network)
    chunks/KEY__A-B.error.json  the error of a chunk that failed

``KEY`` is a hash of the spec's identity and the group's, so results of a changed spec
are never mixed with old ones, and a rerun finds what is already done.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from pathlib import Path
from typing import Any

from etobs.experiments.common import Experiment


def _canonical(obj: Any) -> str:
    return json.dumps(obj, sort_keys=True, separators=(",", ":"), default=repr)


def task_key(spec: Experiment, group: int) -> str:
    """Hash of everything that determines the numbers of one group."""
    ident = {"spec": spec.identity(), "kwargs": spec.group_identity(group)}
    return hashlib.sha256(_canonical(ident).encode()).hexdigest()[:20]


def last_line(failure: dict[str, Any]) -> str:
    """The last line of a stored failure's error (the exception), for reports."""
    text = str(failure.get("error", "")).strip()
    return text.splitlines()[-1] if text else "unknown error"


def atomic_write(path: Path, text: str) -> None:
    """Write ``text`` to ``path`` so that readers see the old file or the whole new one."""
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w") as fh:
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
        """Persist a finished chunk (and forget an earlier failure of the same runs)."""
        name = self._name(key, runs)
        atomic_write(self.chunks / f"{name}.json", _canonical({"key": key, "records": records}))
        (self.chunks / f"{name}.error.json").unlink(missing_ok=True)

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
            try:
                data = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError):
                continue  # unreadable: the runs will be computed again
            for rec in data["records"]:
                if runs is None or int(rec["run"]) < runs:
                    out.setdefault(int(rec["run"]), rec)
        return out

    def errors(self, key: str, present: set[int], runs: int) -> list[dict[str, Any]]:
        """Failures of ``key`` still standing: some of their runs below ``runs`` are missing.

        Error files whose runs have all been stored since (in any chunking) are deleted.
        """
        out = []
        for path in sorted(self.chunks.glob(f"{key}__*.error.json")):
            try:
                err = json.loads(path.read_text())
            except (OSError, json.JSONDecodeError):
                continue
            if set(err["runs"]) <= present:
                path.unlink(missing_ok=True)
            elif any(r < runs and r not in present for r in err["runs"]):
                out.append(err)
        return out

    def clean_temporary(self) -> None:
        """Remove temporary files left by a writer that was killed mid-write."""
        for path in self.chunks.glob(".*.tmp"):
            path.unlink(missing_ok=True)
