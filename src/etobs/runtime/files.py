"""Open the service's and the sensors' files without blocking, and only if they are regular files.

A plain :func:`open` of a FIFO waits for a writer (or a reader) that may never come:
a secret, state, token or sequence file that was a FIFO hung ``etobs serve`` and
``etobs sensor`` in ``open()``. :func:`open_regular` opens with ``O_NONBLOCK`` (which
returns at once on a FIFO or a device), checks with :func:`os.fstat` that what was opened
is a regular file, and raises :class:`~etobs.errors.InputError` with one line naming the
file otherwise. The check is on the file that was opened, so nothing can be swapped in
between. Standard library only (a sensor imports it).
"""

from __future__ import annotations

import os
import stat
from pathlib import Path
from typing import IO

from etobs.errors import InputError

_KINDS = (
    (stat.S_ISDIR, "a folder"),
    (stat.S_ISFIFO, "a FIFO"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
)


def _kind(mode: int) -> str:
    return next((name for test, name in _KINDS if test(mode)), "not a regular file")


def open_regular(
    path: str | os.PathLike[str], what: str, *, write: bool = False, follow: bool = True
) -> IO[bytes]:
    """``path`` opened in binary mode (``"rb"``, or ``"wb"`` with ``write``), refused unless regular.

    Parameters
    ----------
    path : path
        The file.
    what : str
        How errors name it, e.g. ``"`runtime.secret_file`"`` or ``"--trace"``.
    write : bool
        Open for writing: created (mode 600) if missing, emptied *after* the check, so a
        device or a FIFO is never truncated or written.
    follow : bool
        Follow a symbolic link (``False``: ``O_NOFOLLOW``, a link is refused).

    Raises
    ------
    FileNotFoundError
        ``path`` does not exist (and ``write`` is false): the caller decides what that means.
    InputError
        ``path`` is not a regular file, or cannot be opened: one line naming it.

    """
    flags = (os.O_WRONLY | os.O_CREAT) if write else os.O_RDONLY
    flags |= getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_CLOEXEC", 0)
    if not follow:
        flags |= getattr(os, "O_NOFOLLOW", 0)
    name = str(Path(path))
    try:
        fd = os.open(path, flags, 0o600)
    except FileNotFoundError:
        if write:
            raise InputError(f"{what} {name!r} cannot be written: its folder does not exist") from None
        raise
    except OSError as exc:  # ENXIO: a FIFO without a reader; ELOOP: a link with follow=False
        raise InputError(f"{what} {name!r} cannot be opened: {exc.strerror or exc}") from exc
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise InputError(f"{what} {name!r} is {_kind(mode)}, not a regular file; give a plain file")
        if hasattr(os, "set_blocking"):  # regular files never block; plain reads and writes from here
            os.set_blocking(fd, True)
        if write:
            os.ftruncate(fd, 0)
        return os.fdopen(fd, "wb" if write else "rb")
    except BaseException:
        os.close(fd)
        raise
