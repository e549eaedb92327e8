"""Benchmarks time the engine with its code ready: the model and its lane form compiled (or loaded).

The engine does not wait for a model's new lane form: it compiles it on a thread and runs
the first batches lane by lane with the one-run form (the same numbers, 2-4 times
slower). A benchmark that times the engine calls :func:`ready` before its clock starts.
"""

from __future__ import annotations

from typing import Any


def ready(problem: Any, *, shared: bool = True) -> None:
    """Compile or load ``problem``'s engine code, its lane form (``shared``: for runs of one problem) too."""
    from etobs.estimation.compiled import compile_problem

    compile_problem(problem).system.lane_form(shared, True)
