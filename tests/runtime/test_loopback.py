"""The live-run harness (:mod:`tests.runtime.loopback`) gives the same run however loaded the machine.

A loaded machine is simulated by stalling a sensor thread (before it starts, and in the
middle of its run): the stall is injected, and what is asserted is the run's outcome, not
how long it took.
"""

import time

import tests.runtime.loopback as loopback
from etobs import PeriodicRule
from tests.estimation import linear
from tests.runtime.loopback import final_gap, live, reference


def test_a_stalled_sensor_thread_loses_no_sample_and_no_datagram(monkeypatch):
    """A sensor thread that starts 0.6 s of wall time after the epoch (twice the lead the
    harness gives) and stalls 1 s at t = 1 (400 samples overdue, sent at once) through the
    lossy relay: it skipped its first 122 samples (478 of 600 transmissions), the burst
    overflowed the relay's socket buffer (~170 of 601 datagrams never seen, the run waited
    out its 300-s linger and ended 1.29 from the reference, the CI failure's figure); now
    every sample is sent, every datagram reaches the relay and is judged, and the estimate
    ends on the reference. The relay never says it is drained while a datagram it took in
    is not yet sent (it did, for a datagram it did not delay)."""
    run, send = loopback.run, loopback.LossyLink._send
    early = []

    def stalled(node, read, *args, **kwargs):
        time.sleep(0.6)
        stalls = [1.0]

        def slow_read(t):
            if stalls and t >= stalls[0]:
                time.sleep(stalls.pop())
            return read(t)

        return run(node, slow_read, *args, **kwargs)

    def checked_send(self, data, copies):
        early.append(self.drained(self.stats["in"], self.stats["out"]))  # it takes the lock
        send(self, data, copies)

    monkeypatch.setattr(loopback, "run", stalled)
    monkeypatch.setattr(loopback.LossyLink, "_send", checked_send)
    pb = linear.problem(PeriodicRule(0.01))
    _, y, ref = reference(pb, [1.0, -0.5], 6.0, 0.005)
    link = {"loss": 0.2, "duplicate": 0.25, "max_delay": 0.01, "seed": 3, "until": 150}
    snap, _, extra = live(pb, y, 0.005, 6.0, time_scale=4.0, link=link)
    c, st = snap["counts"], extra["link"]
    assert tuple(n.transmissions for n in extra["nodes"]) == ref.transmissions
    assert len(extra["sent"]) == sum(ref.transmissions) + 1 == st["in"]  # with the initial value
    assert sum(c.values()) == st["out"] == st["in"] - st["dropped"] + st["duplicated"]
    assert len(early) == st["in"] - st["dropped"] and not any(early)
    assert final_gap(snap, ref) < 1e-3
