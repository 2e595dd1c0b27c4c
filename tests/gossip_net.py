"""A tiny in-memory network for pure-core tests: literal times, explicit steps, no sockets."""

from __future__ import annotations

import random
from collections.abc import Callable

from sdrpeer.gossip.config import GossipConfig, lan
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import CoreEvent
from sdrpeer.gossip.messages import Addr, Packet
from sdrpeer.vocabulary import MemberState

Drop = Callable[[Addr, Addr, Packet], bool]


def addr(i: int) -> Addr:
    """The address of robot i."""
    return ("10.0.0.1", 7000 + i)


class Net:
    """Cores by address; packets are delivered after `delay` seconds unless `drop` says no."""

    def __init__(self, config: GossipConfig | None = None, delay: float = 0.001) -> None:
        self.config = config or lan()
        self.delay = delay
        self.cores: dict[Addr, Membership] = {}
        self.events: dict[str, list[CoreEvent]] = {}
        self.in_flight: list[tuple[float, Addr, Addr, Packet]] = []
        self.drop: Drop = lambda src, dst, p: False
        self.now = 0.0

    def add(self, i: int, seed: int | None = None) -> Membership:
        """Create robot i (name r<i>) at the current time."""
        core = Membership(f"r{i}", addr(i), self.config, now=self.now, rng=random.Random(seed or i))
        self.cores[core.addr] = core
        self.events.setdefault(core.name, [])
        return core

    def remove(self, core: Membership) -> None:
        """Kill a robot: it vanishes, packets to it are lost."""
        del self.cores[core.addr]

    def _drain(self, core: Membership) -> None:
        for dst, packet in core.datagrams_to_send():
            if not self.drop(core.addr, dst, packet):
                self.in_flight.append((self.now + self.delay, core.addr, dst, packet))
        while (e := core.next_event()) is not None:
            self.events[core.name].append(e)

    def run(self, until: float) -> None:
        """Advance time to `until`, firing timers and delivering packets in time order."""
        for core in list(self.cores.values()):
            self._drain(core)
        while True:
            next_timer = min((c.next_timer() for c in self.cores.values()), default=float("inf"))
            next_packet = min((f[0] for f in self.in_flight), default=float("inf"))
            t = min(next_timer, next_packet)
            if t > until:
                break
            self.now = t
            if next_packet <= next_timer:
                due = [f for f in self.in_flight if f[0] <= t]
                self.in_flight = [f for f in self.in_flight if f[0] > t]
                for _, src, dst, packet in due:
                    receiver = self.cores.get(dst)
                    if receiver is not None:
                        receiver.receive(t, src, packet)
                        self._drain(receiver)
            else:
                for core in list(self.cores.values()):
                    if core.next_timer() <= t:
                        core.handle_timer(t)
                        self._drain(core)
        self.now = until

    def state(self, viewer: Membership, name: str) -> MemberState | None:
        """The state `viewer` holds for `name`."""
        return viewer.state_of(name)
