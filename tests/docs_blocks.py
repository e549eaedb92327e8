"""Run the Python examples of a Markdown page as written (shared by the README's and the docs' tests).

A block fenced as ```` ```python ```` is code to run; one fenced as
```` ```python name.py ```` is a file the reader saves: it is written to the working
folder before any block runs. The blocks run in order, in one namespace, as one script
would; what they print goes to stdout and the namespace is returned for checks.
"""

from __future__ import annotations

import re
import sys
from pathlib import Path
from typing import Any

_BLOCK = re.compile(r"^```python(?: +([\w.-]+\.py))?\n(.*?)^```", re.S | re.M)


def python_blocks(page: Path) -> list[tuple[str | None, str]]:
    """The page's Python blocks in order: ``(file name or None, code)``."""
    return [(name or None, code) for name, code in _BLOCK.findall(page.read_text())]


def run_python_blocks(page: Path, folder: Path | None = None) -> dict[str, Any]:
    """Write the page's file blocks into ``folder``, run its other blocks there; the namespace.

    The caller makes ``folder`` the working directory and importable (e.g. with
    ``monkeypatch.chdir`` and ``monkeypatch.syspath_prepend``) when the page has file blocks.
    """
    blocks = python_blocks(page)
    assert blocks, f"{page.name} has no Python example"
    for name, code in blocks:
        if name is not None:
            assert folder is not None, f"{page.name} has a file block ({name}): give a folder"
            (folder / name).write_text(code)
    namespace: dict[str, Any] = {"__name__": "__main__"}
    for name, code in blocks:
        if name is None:
            exec(compile(code, str(page), "exec"), namespace)
    return namespace


def run_page_in(page: Path, folder: Path, monkeypatch: Any, modules: tuple[str, ...]) -> dict[str, Any]:
    """Run ``page`` in ``folder`` as a reader would: it is the working folder and importable.

    The page's file blocks (``modules``, imported by its other blocks) are forgotten after,
    so that another test's module of the same name is not taken for them.
    """
    monkeypatch.chdir(folder)
    monkeypatch.syspath_prepend(str(folder))
    try:
        return run_python_blocks(page, folder)
    finally:
        for name in modules:
            sys.modules.pop(name, None)
