"""Where compiled code is kept on disk, and numba's cache keyed by content.

The folder is ``$ETOBS_CACHE_DIR`` if set (``off`` disables the cache), else
``$XDG_CACHE_HOME/etobs`` or ``~/.cache/etobs``. Deleting it is always safe.

numba's own cache (``cache=True``) finds a function's machine code by the path and time
stamp of its source file, which lambdas, closures, notebook cells and generated code do
not have. :class:`ContentLocator` keys it by a content hash instead: a function whose
globals hold ``__etobs_key__`` is cached in ``<folder>/functions`` under that key, so
the same code is found again by any process, however the function was written or
imported, and a changed function (or a changed constant it reads) gets a new key.

Every file numba writes under the folder (an entry's index ``.nbi`` and data ``.nbc``,
for the kernels and the functions alike) starts with a SHA-256 of the rest, checked
before numba reads a byte of it (:func:`install_checksums`): random damage to an entry's
machine code crashed Python in LLVM (``BitcodeReader.cpp ... Assertion``), past any
handler, or was loaded silently.
"""

from __future__ import annotations

import hashlib
import io
import os
import pickle
import warnings
from pathlib import Path
from typing import Any

ENV = "ETOBS_CACHE_DIR"
KEY = "__etobs_key__"
_OFF = {"", "0", "off", "none", "false", "no"}
#: First bytes of a cache file written by etobs; the file's SHA-256 (32 bytes) follows, then numba's bytes.
MAGIC = b"etobs-sha256\n"


def cache_dir() -> Path | None:
    """The cache folder, or ``None`` when disabled (see the module docstring)."""
    raw = os.environ.get(ENV)
    if raw is not None:
        if raw.strip().lower() in _OFF:
            return None
        return Path(raw).expanduser()
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg).expanduser() if xdg else Path.home() / ".cache"
    return base / "etobs"


def install_locator() -> None:
    """Put :class:`ContentLocator` first in numba's list of cache locators (once).

    Also key the entries of functions that carry ``__etobs_key__`` by that key alone:
    numba adds a hash of the pickled closure values, and a closure over a compiled
    function (``luenberger``'s model ``f``, say) pickles differently in every process,
    so such a function would never be found again. Our key already covers the closure
    values, by content (:mod:`etobs.compile.fingerprint`).
    """
    from numba.core import caching

    install_checksums()
    locators = caching.CacheImpl._locator_classes
    if not any(getattr(c, "__name__", "") == "ContentLocator" for c in locators):
        locators.insert(0, _locator_class(caching._CacheLocator))
    index_key = getattr(caching.Cache, "_index_key", None)
    if index_key is None:  # another numba layout: such functions are compiled again, no harm
        return
    if not getattr(index_key, "_etobs", False):

        def _index_key(self: Any, sig: Any, codegen: Any) -> Any:
            key = getattr(self._py_func, "__globals__", {}).get(KEY)
            if key is None:
                return index_key(self, sig, codegen)
            return (sig, codegen.magic_tuple(), ("etobs", key))

        _index_key._etobs = True  # type: ignore[attr-defined]
        caching.Cache._index_key = _index_key


def install_checksums() -> None:
    """Write a SHA-256 into each cache file numba writes under :func:`cache_dir`, check it on load (once).

    A file written by etobs is :data:`MAGIC`, the SHA-256 of numba's bytes, then those
    bytes, written in one piece (numba writes a private file and renames it into place),
    so a file and its checksum never disagree but by damage. On load, the whole file is
    read and checked before numba unpickles it or LLVM parses its machine code; a file
    whose checksum is wrong, or that has none, is treated as absent, with one warning:
    numba compiles the function and writes the entry again (no exception, so it works at
    any depth: a helper compiled inside the estimation model as well). A cache written
    before etobs checked its files has no checksum and is discarded the same way, with
    one warning in all: its bytes cannot be told from damaged ones, and trusting them is
    what crashed Python. Files of numba caches
    elsewhere (the user's own ``cache=True`` functions) are left as numba writes them.
    Cost: one SHA-256 pass over the entry at load (about 1 ms per MB).
    """
    from numba.core import caching

    cls = caching.IndexDataCacheFile
    if getattr(cls._load_data, "_etobs", False):
        return
    numba_ = {name: getattr(cls, name) for name in ("_save_index", "_load_index", "_save_data", "_load_data")}

    def _save_index(self: Any, overloads: dict) -> None:
        if not _ours(self._cache_path):
            return numba_["_save_index"](self, overloads)
        body = pickle.dumps(self._version, protocol=-1) + self._dump((self._source_stamp, overloads))
        with self._open_for_write(self._index_path) as f:
            f.write(_sealed(body))

    def _load_index(self: Any) -> dict:
        if not _ours(self._cache_path):
            return numba_["_load_index"](self)
        try:
            raw = Path(self._index_path).read_bytes()
        except FileNotFoundError:
            return {}
        body = _opened(raw, self._index_path)
        if body is None:
            return {}
        stream = io.BytesIO(body)
        if pickle.load(stream) != self._version:  # another numba wrote it: not ours to read
            return {}
        stamp, overloads = pickle.loads(stream.read())
        return overloads if stamp == self._source_stamp else {}

    def _save_data(self: Any, name: str, data: Any) -> None:
        if not _ours(self._cache_path):
            return numba_["_save_data"](self, name, data)
        with self._open_for_write(self._data_path(name)) as f:
            f.write(_sealed(self._dump(data)))

    def _load_data(self: Any, name: str) -> Any:
        if not _ours(self._cache_path):
            return numba_["_load_data"](self, name)
        path = self._data_path(name)
        body = _opened(Path(path).read_bytes(), path)
        return None if body is None else pickle.loads(body)  # None: no entry, numba compiles

    for method in (_save_index, _load_index, _save_data, _load_data):
        method._etobs = True  # type: ignore[attr-defined]
        setattr(cls, method.__name__, method)


def _ours(path: str) -> bool:
    folder = cache_dir()
    return folder is not None and Path(path).is_relative_to(folder)


def _sealed(body: bytes) -> bytes:
    return MAGIC + hashlib.sha256(body).digest() + body


def _opened(raw: bytes, path: str) -> bytes | None:
    """The bytes numba wrote to ``path``, checked by their SHA-256; ``None`` (one warning) if unverified."""
    name = Path(path).name
    if not raw.startswith(MAGIC):
        _warn(
            "etobs: the compile cache has files without a checksum (written before etobs checked them, "
            f"{name} first); discarded them and compiled them again"
        )
        return None
    digest, body = raw[len(MAGIC) : len(MAGIC) + 32], raw[len(MAGIC) + 32 :]
    if hashlib.sha256(body).digest() != digest:
        _warn(
            f"etobs: the compile cache file {name} does not match its SHA-256: damaged; "
            "discarded it and compiled it again"
        )
        return None
    return body


_WARNED: set[str] = set()


def _warn(message: str) -> None:
    key = message.split("(")[0] if "without a checksum" in message else message  # an old cache: one warning
    if key not in _WARNED:
        _WARNED.add(key)
        warnings.warn(message, RuntimeWarning, stacklevel=2)


def discard(keys: list[str]) -> int:
    """Delete the cache entries of the functions keyed by ``keys`` (a damaged entry); how many files.

    An entry is an index (``.nbi``) and data (``.nbc``) files whose names end in the
    key's disambiguator (:class:`ContentLocator`); deleting them is always safe.
    """
    folder = cache_dir()
    if folder is None:
        return 0
    gone = 0
    for key in keys:
        for path in (folder / "functions").glob(f"*-{_disambiguator(key)}.*"):
            if path.suffix in (".nbi", ".nbc"):
                path.unlink(missing_ok=True)
                gone += 1
    return gone


def _disambiguator(key: str) -> str:
    # the whole key (the function's hash and how it is called) names the file
    return hashlib.sha256(key.encode()).hexdigest()[:24]


def _locator_class(base: type) -> type:
    class ContentLocator(base):  # type: ignore[misc, valid-type]
        """Finds a function's cached code by the key in its globals (module docstring)."""

        def __init__(self, key: str, folder: Path) -> None:
            self._key = key
            self._folder = folder
            # numba names this file in its warnings (a function it cannot cache); without it,
            # its warning raised AttributeError and the cached code was never loaded
            self._py_file = f"<etobs function {key}>"

        def get_cache_path(self) -> str:
            return str(self._folder)

        def get_source_stamp(self) -> Any:
            return self._key

        def get_disambiguator(self) -> str:
            return _disambiguator(self._key)

        @classmethod
        def from_function(cls, py_func: Any, py_file: str) -> Any:
            key = getattr(py_func, "__globals__", {}).get(KEY)
            folder = cache_dir()
            if key is None or folder is None:
                return None
            return cls(key, folder / "functions")

    return ContentLocator
