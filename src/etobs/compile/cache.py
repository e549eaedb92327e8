"""Where compiled code is kept on disk, and numba's cache keyed by content.

The folder is ``$ETOBS_CACHE_DIR`` if set (``off`` disables the cache), else
``$XDG_CACHE_HOME/etobs`` or ``~/.cache/etobs``. Deleting it is always safe.

numba's own cache (``cache=True``) finds a function's machine code by the path and time
stamp of its source file, which lambdas, closures, notebook cells and generated code do
not have. :class:`ContentLocator` keys it by a content hash instead: a function whose
globals hold ``__etobs_key__`` is cached in ``<folder>/functions`` under that key, so
the same code is found again by any process, however the function was written or
imported, and a changed function (or a changed constant it reads) gets a new key.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

ENV = "ETOBS_CACHE_DIR"
KEY = "__etobs_key__"
_OFF = {"", "0", "off", "none", "false", "no"}


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
