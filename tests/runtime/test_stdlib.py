"""The sensor side runs with the standard library alone (numpy, scipy, numba blocked)."""

import subprocess
import sys

CODE = r"""
import math, sys

class Block:
    def find_spec(self, name, path=None, target=None):
        if name.split(".")[0] in ("numpy", "scipy", "numba", "matplotlib", "cvxpy"):
            raise ImportError("blocked for this test: " + name)

sys.meta_path.insert(0, Block())

from etobs.runtime.packet import decode, node_keys
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode, SequenceStore, run

keys = node_keys(b"s", [0])
spec = {"kind": "dynamic", "gamma": ["quadratic", 5.0], "alpha": ["linear", 2.0], "sigma": 0.5,
        "c": 0.1, "b": 1.0, "eps": 0.01, "eta0": 0.1}

# run() on a clock of the test's own, which moves only when the node sleeps: no sample
# depends on how fast the machine is
clock = [1.7e9]
out = []
node = SensorNode(0, keys[0], SampledRule(spec, 0.01), out.append, SequenceStore(), session=clock[0])
samples = run(node, lambda t: [math.sin(3 * t)], 0.01, 2.0, epoch=clock[0], time_scale=1.0,
              clock=lambda: clock[0], sleep=lambda s: clock.__setitem__(0, clock[0] + s))
# the same node stepped by hand: run() took every sample at its time
by_hand = SensorNode(0, keys[0], SampledRule(spec, 0.01), [].append, SequenceStore())
# the initial value at k = 0, then the transmissions
sent = [k for k in range(201) if by_hand.sample(0.01 * k, [math.sin(3 * 0.01 * k)]) is not None]
last = decode(out[-1], keys)
times = [decode(d, keys).t for d in out]
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy", "numba"))
print(samples, node.transmissions, by_hand.transmissions, len(out), last.seq, last.session == 1.7e9,
      times == [0.01 * k for k in sent], heavy)
"""


def test_sensor_node_needs_only_the_standard_library():
    proc = subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, timeout=300, check=False
    )
    assert proc.returncode == 0, proc.stderr
    samples, transmissions, by_hand, packets, last_seq, session, same_times, heavy = proc.stdout.split(
        maxsplit=7
    )
    assert int(samples) == 201 and int(transmissions) == int(by_hand) > 5
    assert int(packets) == int(transmissions) + 1 == int(last_seq)  # + the initial value
    assert session == same_times == "True"  # every packet at its sample's time, in the session
    assert heavy.strip() == "[]"
