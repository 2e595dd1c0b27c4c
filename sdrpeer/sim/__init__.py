"""Deterministic simulation: many membership cores on a virtual clock over a lossy network.

How it works: `Cluster` owns one event heap (datagram deliveries, core deadlines, scheduled
actions) and a `Network` (seeded delay, loss, partitions); every core event lands in a `Trace`
with its virtual time. Everything random derives from one seed, so a run replays exactly.
"""

from sdrpeer.sim.cluster import Cluster, Core, CoreFactory, membership_factory, packet_size
from sdrpeer.sim.network import DROPPED, Network
from sdrpeer.sim.trace import Trace

__all__ = [
    "DROPPED",
    "Cluster",
    "Core",
    "CoreFactory",
    "Network",
    "Trace",
    "membership_factory",
    "packet_size",
]
