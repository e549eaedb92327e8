"""``python -m tests.runtime.virtual_clock START ARGS...``: ``etobs ARGS...`` on a virtual wall clock.

``time.time()`` is ``START`` plus the seconds the process has slept (``time.sleep`` still
sleeps, so packets keep their pace), never the seconds it spent computing: a process
slowed down by a loaded machine sees the same clock as one on an idle machine. The
clock is installed before etobs is imported, so the defaults ``clock=time.time`` and
``sleep=time.sleep`` of :func:`etobs.runtime.sensor.run` are these.
"""

import sys
import time

_now = [float(sys.argv[1])]
_sleep = time.sleep


def _time() -> float:
    return _now[0]


def _slept(seconds: float) -> None:
    _sleep(seconds)
    _now[0] += max(0.0, seconds)


time.time = _time
time.sleep = _slept

from etobs.cli.main import main  # noqa: E402 - after the clock is installed

sys.exit(main(sys.argv[2:]))
