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

import time  # a clock that moves only when the node sleeps: the run does not depend on the load

clock = [1000.0]
time.time = lambda: clock[0]
time.sleep = lambda s: clock.__setitem__(0, clock[0] + s)

from etobs.runtime.packet import decode, node_keys
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode, SequenceStore, run

keys = node_keys(b"s", [0])
out = []
spec = {"kind": "dynamic", "gamma": ["quadratic", 5.0], "alpha": ["linear", 2.0], "sigma": 0.5,
        "c": 0.1, "b": 1.0, "eps": 0.01, "eta0": 0.1}
node = SensorNode(0, keys[0], SampledRule(spec, 0.01), out.append, SequenceStore())
samples = run(node, lambda t: [math.sin(3 * t)], 0.01, 2.0, time_scale=1e6)
last = decode(out[-1], keys)
heavy = sorted(m for m in sys.modules if m.split(".")[0] in ("numpy", "scipy", "numba"))
print(samples, node.transmissions, len(out), last.seq, heavy)
"""


def test_sensor_node_needs_only_the_standard_library():
    proc = subprocess.run(
        [sys.executable, "-c", CODE], capture_output=True, text=True, timeout=60, check=False
    )
    assert proc.returncode == 0, proc.stderr
    samples, transmissions, packets, last_seq, heavy = proc.stdout.split(maxsplit=4)
    assert int(samples) == 201 and int(transmissions) > 5
    assert int(packets) == int(transmissions) + 1 == int(last_seq)  # + the initial value
    assert heavy.strip() == "[]"
