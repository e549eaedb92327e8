"""Per-node high-water marks of the observer service, kept in a file across restarts.

The observer refuses a packet whose sequence number is not above the highest one it has
applied from that node (:mod:`etobs.runtime.service`). Held in memory only, that mark was
lost when the service restarted, and every packet captured before the restart was then
accepted again. :class:`HighWaterMarks` writes the marks to a file, atomically (a
temporary file, ``fsync``, :func:`os.replace`, ``fsync`` of the folder) *before* the
packets they cover are applied, so after a crash at any point no packet that acted on the
estimate is accepted again. Each mark is stored with the id of the node's key
(:func:`~etobs.runtime.packet.key_id`): marks of another key (the secret was rotated)
mean nothing for the new one and are not loaded. The file is written with mode 600, and
one that the group or others may write is refused: lowering a mark lets the packets
above it in again.

The observer state is written with the marks, in the same atomic write (version 2): a
service restarted on the same session resumes from it (``t``, ``z``, ``ybar`` and the
packets accepted but not yet applied) instead of waiting for every node to send again.
The file is JSON::

    {"format": "etobs-high-water-marks", "version": 2,
     "nodes": {"0": {"key": "1f2e...", "seq": 4096}, ...},
     "observer": {"session": 1764772189.5, "t": 4.2, "z": [...], "ybar": [...],
                  "nonfinite": false, "heard": [0, 1],
                  "queue": [[t_applied, node, seq, t, [values], initial], ...]}}

Version 1 files (marks only) are read; the state file is opened without blocking and
refused unless it is a regular file (:func:`~etobs.runtime.files.open_regular`).
"""

from __future__ import annotations

import json
import math
import os
import stat
from collections.abc import Mapping
from pathlib import Path
from typing import Any

from etobs.errors import InputError
from etobs.runtime.files import open_regular

FORMAT = "etobs-high-water-marks"
#: Largest state file read: a mark is about 60 bytes, and a deployment has at most 65,536 nodes.
MAX_BYTES = 1 << 23


class HighWaterMarks:
    """The high-water marks of a service in the file ``path`` (created on first save).

    Parameters
    ----------
    path : path
        The state file. A damaged file is an error, not an empty state: starting from
        nothing would accept every old packet again.

    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self.path = Path(path)
        #: The observer state last loaded (:meth:`load`), or None.
        self.observer: dict[str, Any] | None = None

    def load(self, key_ids: Mapping[int, str]) -> dict[int, int]:
        """The stored mark of each node whose key id is ``key_ids[node]`` (others: none)."""
        try:
            with open_regular(self.path, "the high-water marks", follow=False) as fh:
                mode = stat.S_IMODE(os.fstat(fh.fileno()).st_mode)
                text = fh.read(MAX_BYTES + 1).decode()
        except FileNotFoundError:
            return {}
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read the high-water marks {str(self.path)!r}: {exc}") from exc
        if os.name == "posix" and mode & 0o022:
            raise InputError(
                f"the high-water marks {str(self.path)!r} have mode {mode:04o}: the group or others may "
                f"change them, and lowered marks let captured packets in again; run `chmod 600 {self.path}`"
            )
        try:
            raw = json.loads(text)
            if raw.get("format") != FORMAT or raw.get("version") not in (1, 2):
                raise ValueError(f"format {raw.get('format')!r} version {raw.get('version')!r}")
            marks = {}
            for name, entry in raw["nodes"].items():
                node, key, seq = int(name), entry["key"], entry["seq"]
                if not isinstance(seq, int) or not 0 <= seq < 2**64 or not isinstance(key, str):
                    raise ValueError(f"node {name}: seq {seq!r}, key {key!r}")
                if key_ids.get(node) == key:
                    marks[node] = seq
            self.observer = _observer(raw["observer"]) if raw.get("observer") is not None else None
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            raise InputError(
                f"the high-water marks {str(self.path)!r} are damaged ({exc}); they guard against "
                "replayed packets: restore the file, or rotate the secret (new keys) and remove it"
            ) from exc
        return marks

    def save(self, marks: Mapping[int, tuple[str, int]], observer: dict[str, Any] | None = None) -> None:
        """Write ``{node: (key id, seq)}`` and the observer state durably (atomic replace, ``fsync``)."""
        body = {
            "format": FORMAT,
            "version": 2,
            "nodes": {str(i): {"key": k, "seq": s} for i, (k, s) in sorted(marks.items())},
            "observer": observer,
        }
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")  # per process
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            # mode 600: whoever may write the marks may lower them (load refuses a file others may write)
            with open_regular(tmp, "the high-water marks' temporary file", write=True, follow=False) as fh:
                os.fchmod(fh.fileno(), 0o600)  # an old temporary file keeps its mode otherwise
                fh.write(json.dumps(body, allow_nan=False).encode())
                fh.flush()
                os.fsync(fh.fileno())
            os.replace(tmp, self.path)
            if hasattr(os, "O_DIRECTORY"):  # the rename itself must survive a power loss
                fd = os.open(self.path.parent, os.O_RDONLY | os.O_DIRECTORY)
                try:
                    os.fsync(fd)
                finally:
                    os.close(fd)
        except OSError as exc:
            raise InputError(
                f"cannot write the high-water marks {str(self.path)!r}: {exc}; the service stops "
                "rather than apply packets it could not guard against replay"
            ) from exc


def _observer(raw: Any) -> dict[str, Any]:
    """The observer state of a state file, checked for types (``ValueError`` if it is not one)."""

    def finite(v: Any, none: bool = False) -> bool:
        return (v is None and none) or (
            isinstance(v, int | float) and not isinstance(v, bool) and math.isfinite(v)
        )

    ok = (
        isinstance(raw, dict)
        and finite(raw.get("session"))
        and finite(raw.get("t"))
        and isinstance(raw.get("z"), list)
        and all(finite(v) for v in raw["z"])
        and isinstance(raw.get("ybar"), list)
        and all(finite(v, none=True) for v in raw["ybar"])
        and isinstance(raw.get("nonfinite"), bool)
        and isinstance(raw.get("heard"), list)
        and all(isinstance(i, int) for i in raw["heard"])
        and isinstance(raw.get("queue"), list)
        and all(
            isinstance(raw.get(key, []), list)
            and all(isinstance(v, int) and v >= 0 for v in raw.get(key, []))
            for key in ("transmissions", "gaps")
        )
        and isinstance(raw.get("addresses", []), list)
        and all(
            a is None or (isinstance(a, list) and len(a) == 2 and isinstance(a[0], str) and type(a[1]) is int)
            for a in raw.get("addresses", [])
        )
    )
    for entry in raw.get("queue", []) if ok else []:
        ok = ok and (
            isinstance(entry, list)
            and len(entry) == 6
            and finite(entry[0])
            and isinstance(entry[1], int)
            and isinstance(entry[2], int)
            and finite(entry[3])
            and isinstance(entry[4], list)
            and all(finite(v) for v in entry[4])
            and isinstance(entry[5], bool)
        )
    if not ok:
        raise ValueError("the observer state is not one")
    return raw
