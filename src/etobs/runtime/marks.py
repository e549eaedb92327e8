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

The file is JSON::

    {"format": "etobs-high-water-marks", "version": 1,
     "nodes": {"0": {"key": "1f2e...", "seq": 4096}, ...}}
"""

from __future__ import annotations

import json
import os
import stat
from collections.abc import Mapping
from pathlib import Path

from etobs.errors import InputError

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

    def load(self, key_ids: Mapping[int, str]) -> dict[int, int]:
        """The stored mark of each node whose key id is ``key_ids[node]`` (others: none)."""
        try:
            with open(self.path, "rb") as fh:
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
            if raw.get("format") != FORMAT or raw.get("version") != 1:
                raise ValueError(f"format {raw.get('format')!r} version {raw.get('version')!r}")
            marks = {}
            for name, entry in raw["nodes"].items():
                node, key, seq = int(name), entry["key"], entry["seq"]
                if not isinstance(seq, int) or not 0 <= seq < 2**64 or not isinstance(key, str):
                    raise ValueError(f"node {name}: seq {seq!r}, key {key!r}")
                if key_ids.get(node) == key:
                    marks[node] = seq
        except (ValueError, TypeError, KeyError, AttributeError) as exc:
            raise InputError(
                f"the high-water marks {str(self.path)!r} are damaged ({exc}); they guard against "
                "replayed packets: restore the file, or rotate the secret (new keys) and remove it"
            ) from exc
        return marks

    def save(self, marks: Mapping[int, tuple[str, int]]) -> None:
        """Write ``{node: (key id, seq)}`` durably (atomic replace, ``fsync``)."""
        body = {
            "format": FORMAT,
            "version": 1,
            "nodes": {str(i): {"key": k, "seq": s} for i, (k, s) in sorted(marks.items())},
        }
        tmp = self.path.with_name(f".{self.path.name}.{os.getpid()}.tmp")  # per process
        try:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            # mode 600: whoever may write the marks may lower them (load refuses a file others may write)
            with os.fdopen(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600), "w") as fh:
                os.fchmod(fh.fileno(), 0o600)  # an old temporary file keeps its mode otherwise
                json.dump(body, fh)
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
