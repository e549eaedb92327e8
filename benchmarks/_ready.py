"""Benchmarks time the engine with its code ready: the model and its lane form compiled (or loaded).

A model's lane form is compiled (or loaded from the disk cache) when a batch first fills
16 lanes, not by a warm-up of one run. A benchmark that times the engine calls
:func:`ready` before its clock starts, so that the first timed batch does not compile it.
"""

from __future__ import annotations

from typing import Any


def ready(problem: Any, *, shared: bool = True) -> None:
    """Compile or load ``problem``'s engine code, its lane form (``shared``: for runs of one problem) too."""
    from etobs.estimation.compiled import compile_problem

    compile_problem(problem).system.lane_form(shared)
