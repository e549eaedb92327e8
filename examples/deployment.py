"""
Deployment: sensor nodes and the observer service
=================================================

Run the robot arm's rules as sensor nodes that send authenticated packets, and the
observer service that integrates the observer on them, in this process (no sockets);
the service's estimate matches the offline reference of the deployment.
"""

# %%
# Samples and the offline reference
# ---------------------------------
# Each node samples its output ``ytilde_i(t_k)`` at ``t_k = k T`` (``T`` = 2 ms, as in
# ``etobs demo live``) and decides there with the paper's rule. ``replay`` runs the very
# sensor nodes and observer service of a deployment on those samples, with no network.
import numpy as np

from etobs import simulate, transmission_counts
from etobs.examples import X0_PAPER, robot_arm
from etobs.plot import plot_trace
from etobs.runtime.packet import node_keys
from etobs.runtime.replay import replay, sample_outputs
from etobs.runtime.sampled_rule import SampledRule
from etobs.runtime.sensor import SensorNode
from etobs.runtime.service import ObserverCore

problem = robot_arm()
T, duration = 0.002, 6.0
keys = node_keys(b"a deployment secret, never a constant in real use", range(problem.n_nodes))
t, y = sample_outputs(problem, X0_PAPER, duration, T)
reference = replay(problem, keys, t, y, T)
print("reference transmissions:", reference.transmissions)
print(
    "simulator, Sampled rule:", transmission_counts(simulate(robot_arm(sample_period=T), X0_PAPER, duration))
)

# %%
# The nodes and the service, packet by packet
# -------------------------------------------
# The nodes hand their packets (bytes, with an HMAC tag) to a "radio" that delivers them
# 6 ms later. The service (``ObserverCore``, what ``etobs serve`` runs) checks each one,
# keeps its observer ``hold_back`` = 50 ms behind its clock so that late packets still act
# from their sample time, and writes a trace line every 10 ms.
session, delay, hold_back, tick = 1.0, 0.006, 0.05, 0.01
service = ObserverCore(problem, keys, session=session)
radio, in_flight, delivered, lines = [], [], [], []
nodes = [
    SensorNode(i, keys[i], SampledRule(nd.rule.sensor_spec(), T), radio.append, session=session)
    for i, nd in enumerate(problem.nodes)
]
for k, now in enumerate(np.append(t, duration + tick * np.arange(1, 7))):  # then run out the hold-back
    if k < len(t):  # each node samples its output ytilde_i(t_k) and may send
        for node, nd in zip(nodes, problem.nodes, strict=True):
            node.sample(float(now), y[k, list(nd.outputs)])
    in_flight += [(now + delay, data) for data in radio]
    radio.clear()
    while in_flight and in_flight[0][0] <= now + 1e-9:
        delivered.append(in_flight.pop(0)[1])
        service.receive(delivered[-1], now=now)
    while len(lines) * tick <= min(now - hold_back, duration) + 1e-9:
        service.advance(len(lines) * tick)
        lines.append(service.snapshot())
trace = {"t": np.array([s["t"] for s in lines]), "xhat": np.array([s["xhat"] for s in lines], dtype=float)}
print("service transmissions:", lines[-1]["transmissions"], "late:", lines[-1]["late"])

# %%
# The service against the reference
# ---------------------------------
# The service applied every packet at its sample time, so its estimate is the reference's
# (``plot_trace`` draws it dashed). A packet replayed, or changed by one bit without the key,
# is refused and leaves the estimate alone.
gap = np.abs(trace["xhat"] - reference.xhat[np.searchsorted(reference.t, trace["t"] - 1e-9)]).max()
print(f"largest gap to the reference: {gap:.2e}")
captured = bytearray(delivered[-1])  # the last packet, as anyone on the network saw it
print("replayed:", service.receive(bytes(captured), now=duration))
captured[-1] ^= 1
print("tampered:", service.receive(bytes(captured), now=duration))
fig, axes = plot_trace(trace, reference)
