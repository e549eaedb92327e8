"""``python -m tests.runtime.virtual_clock START ARGS...``: ``etobs ARGS...`` on a virtual wall clock.

``time.time()`` is ``START`` plus the seconds the process has slept (``time.sleep`` still
sleeps, so packets keep their pace), never the seconds it spent computing: a process
slowed down by a loaded machine sees the same clock as one on an idle machine. The
clock is installed before etobs is imported, so the defaults ``clock=time.time`` and
``sleep=time.sleep`` of :func:`etobs.runtime.sensor.run` are these.
"""

import sys
import time


def _install(start: float) -> None:
    """Replace ``time.time`` and ``time.sleep`` by the virtual clock starting at ``start``."""
    now = [start]
    sleep = time.sleep

    def _time() -> float:
        return now[0]

    def _slept(seconds: float) -> None:
        sleep(seconds)
        now[0] += max(0.0, seconds)

    time.time = _time
    time.sleep = _slept


if __name__ == "__main__":
    # Only as a program: pytest --doctest-modules imports this file, and the clock must
    # not be installed in the test process itself.
    _install(float(sys.argv[1]))
    from etobs.cli.main import main  # after the clock is installed

    sys.exit(main(sys.argv[2:]))
