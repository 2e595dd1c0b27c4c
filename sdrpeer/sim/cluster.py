"""A deterministic cluster: N membership cores on a virtual clock over a simulated network.

How it works:
- one heap of `(time, seq, node, src, item)` tuples drives everything: `src` set means a datagram
  (`item` is the packet) for `node`; `item is None` is a deadline timer of `node`; anything else is
  a scheduled callable (a boot, a kill at a given time);
- after every call into a core the cluster drains it: its outbox goes through `Network.verdict`
  (delay or drop) onto the heap, its events into the `Trace`, and its `next_timer()` is pushed
  only when it changed; older timer entries are skipped when popped (lazy invalidation);
- a killed node receives nothing and its timers stop; `restart` puts a fresh core (incarnation 0,
  same name and address) in its slot and joins it through the seeds;
- every random draw derives from the one `seed`: the network has its own RNG, and each core gets
  `random.Random(f"{seed}/{name}/{generation}")`, so a run with the same seed replays exactly.
"""

from __future__ import annotations

import functools
import heapq
import itertools
import math
import random
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import TYPE_CHECKING, Any, Protocol

from sdrpeer.gossip.config import GossipConfig
from sdrpeer.gossip.events import CoreEvent
from sdrpeer.gossip.messages import Addr, Packet
from sdrpeer.gossip.wire import OVERHEAD, packet_body
from sdrpeer.sim.network import Network
from sdrpeer.sim.trace import Trace
from sdrpeer.vocabulary import MemberState

if TYPE_CHECKING:
    from sdrpeer.gossip.table import MemberInfo


class Core(Protocol):
    """What the simulator needs of a membership core (`sdrpeer.gossip.core.Membership`)."""

    name: str
    addr: Addr

    def join(self, now: float, seeds: Sequence[Addr]) -> None: ...
    def leave(self, now: float) -> None: ...
    def receive(self, now: float, src: Addr, packet: Packet) -> None: ...
    def handle_timer(self, now: float) -> None: ...
    def next_timer(self) -> float: ...
    def datagrams_to_send(self) -> list[tuple[Addr, Packet]]: ...
    def next_event(self) -> CoreEvent | None: ...
    def set_record(self, now: float, payload: bytes, *, urgent: bool = False) -> int: ...
    def broadcast_event(self, now: float, kind: str, payload: bytes) -> None: ...
    def members(self) -> list[MemberInfo]: ...
    def state_of(self, name: str) -> MemberState | None: ...


CoreFactory = Callable[[str, Addr, GossipConfig, float, random.Random], Core]
"""Builds one core: (name, addr, config, now, rng) -> core."""

_MAX_SPINS = 10_000


def membership_factory(
    name: str, addr: Addr, config: GossipConfig, now: float, rng: random.Random
) -> Core:
    """The real core, `sdrpeer.gossip.core.Membership`."""
    from sdrpeer.gossip.core import Membership  # noqa: PLC0415 - keeps `sdrpeer.sim` light

    return Membership(name, addr, config, now=now, rng=rng)


def packet_size(packet: Packet) -> int:
    """Bytes one datagram takes on the wire: `len(packet_body(p)) + OVERHEAD`."""
    return len(packet_body(packet)) + OVERHEAD


class Cluster:
    """N simulated robots, named r0000..., joined through the first `n_seeds` of them."""

    def __init__(
        self,
        n: int,
        config: GossipConfig,
        *,
        seed: int = 0,
        n_seeds: int = 1,
        base_delay: float = 0.001,
        jitter: float = 0.004,
        loss: float = 0.0,
        count_bytes: bool = True,
        trace: bool = False,
        core_factory: CoreFactory = membership_factory,
        names: Sequence[str] | None = None,
    ) -> None:
        """`names`: the robots' names (default r0000, r0001, ...; a calibration against real
        agents uses theirs, since every datagram carries names)."""
        self.config = config
        self.seed = seed
        self.now = 0.0
        self.names = list(names) if names is not None else [f"r{i:04d}" for i in range(n)]
        if len(self.names) != n or len(set(self.names)) != n:
            raise ValueError(f"need {n} distinct names, got {len(set(self.names))}")
        self.addrs: list[Addr] = [(f"10.0.{i // 200}.{i % 200 + 10}", 7946) for i in range(n)]
        self.index = {name: i for i, name in enumerate(self.names)}
        self._by_addr = {addr: i for i, addr in enumerate(self.addrs)}
        self.network = Network(
            n, random.Random(f"{seed}/network"), base_delay=base_delay, jitter=jitter, loss=loss
        )
        self.trace = Trace(self.names, keep_all=trace)
        self._factory = core_factory
        self._seeds = list(range(min(max(n_seeds, 1), n)))
        self._cores: list[Core | None] = [None] * n
        self._up = [False] * n
        self._generation = [0] * n
        self._timer_at = [math.inf] * n
        self._last_fire = [-1.0] * n
        self._spins = 0
        self._unbooted: set[int] = set()
        self._heap: list[tuple[float, int, int, Any, Any]] = []
        self._seq = itertools.count()
        self._size: Callable[[Packet], int] | None = packet_size if count_bytes else None
        self.sent_datagrams = [0] * n
        """Datagrams each node has sent (dropped ones included)."""
        self.sent_bytes = [0] * n
        """Bytes each node has sent (0 unless count_bytes)."""
        self.unroutable = 0
        """Datagrams addressed to no node of the cluster."""

    @property
    def count_bytes(self) -> bool:
        """Whether sent bytes are counted (encoding every datagram costs time)."""
        return self._size is not None

    @count_bytes.setter
    def count_bytes(self, on: bool) -> None:
        self._size = packet_size if on else None

    # -- set-up and faults --------------------------------------------------------------------

    def start(self, spread: float = 0.0) -> None:
        """Boot every node; node i > 0 boots at a seeded time in [now, now + spread)."""
        rng = random.Random(f"{self.seed}/boot")
        self._unbooted.update(range(len(self.names)))
        for i in range(len(self.names)):
            at = self.now + (rng.random() * spread if i and spread else 0.0)
            self.schedule(at, functools.partial(self._boot, i))
        self.run_until(self.now)

    def start_converged(self, records: Mapping[str, bytes] | None = None) -> None:
        """Boot every node as a member of a fleet that has already converged: each knows all
        the others alive and holds `records` (name -> payload, version 1 of each), without the
        join storm (at thousands of nodes the simulator could not afford it; the trace's views
        are not filled either, so use it for what happens after the start: deaths, traffic).
        The cores must have `preload` (`Membership` has)."""
        members = list(zip(self.names, self.addrs, strict=True))
        held = {name: (1, payload) for name, payload in (records or {}).items()}
        for i, name in enumerate(self.names):
            rng = random.Random(f"{self.seed}/{name}/{self._generation[i]}")
            core = self._factory(name, self.addrs[i], self.config, self.now, rng)
            preload = getattr(core, "preload", None)
            if preload is None:
                raise TypeError(f"{type(core).__name__} cannot start converged")
            preload(self.now, members, held)
            self._cores[i] = core
            self._up[i] = True
            self._timer_at[i] = math.inf
            self.trace.up(i, self.now)
            self._drive(i, core, self.now)

    def schedule(self, at: float, action: Callable[[], object]) -> None:
        """Run `action()` at virtual time `at` (a kill, a restart, a set_record...)."""
        heapq.heappush(self._heap, (max(at, self.now), next(self._seq), -1, None, action))

    def kill(self, name: str) -> None:
        """Crash `name`: it stops receiving, its timers stop, datagrams to it vanish."""
        i = self.index[name]
        if not self._up[i]:
            raise ValueError(f"{name} is already down")
        self._up[i] = False
        self._timer_at[i] = math.inf
        self.trace.down(i, self.now)

    def restart(self, name: str) -> None:
        """Bring `name` back as a fresh core (incarnation 0, same address) joining via seeds."""
        i = self.index[name]
        if self._up[i]:
            raise ValueError(f"{name} is up; kill it first")
        self._generation[i] += 1
        self._boot(i)

    def leave(self, name: str) -> None:
        """Let `name` announce a graceful leave (it stays up until killed)."""
        i = self.index[name]
        core = self._call(i)
        core.leave(self.now)
        self._drive(i, core, self.now)

    def partition(self, *groups: Iterable[str]) -> None:
        """Split the network: each group of names is a side; unnamed nodes form one more side."""
        self.network.partition([[self.index[name] for name in g] for g in groups])

    def heal(self) -> None:
        """Remove the partition."""
        self.network.heal()

    def set_loss(self, rate: float) -> None:
        """Set the loss rate of every link without an override."""
        self.network.loss = rate

    def set_link_loss(self, a: str, b: str, rate: float, *, both_ways: bool = True) -> None:
        """Override the loss rate of the link between `a` and `b`."""
        self.network.set_link_loss(self.index[a], self.index[b], rate, both_ways=both_ways)

    # -- driving cores ------------------------------------------------------------------------

    def core(self, name: str) -> Core:
        """The current core of `name` (the last one, if it is down)."""
        core = self._cores[self.index[name]]
        if core is None:
            raise ValueError(f"{name} has not booted yet")
        return core

    def is_up(self, name: str) -> bool:
        """Whether `name` is running."""
        return self._up[self.index[name]]

    def up_names(self) -> list[str]:
        """Names of the running nodes."""
        return [name for name, up in zip(self.names, self._up, strict=True) if up]

    def set_record(self, name: str, payload: bytes, *, urgent: bool = False) -> int:
        """Publish a new record of `name` now (`urgent`: in a gossip round at once); returns
        its version."""
        i = self.index[name]
        core = self._call(i)
        version = core.set_record(self.now, payload, urgent=urgent)
        self._drive(i, core, self.now)
        return version

    def set_vitals(self, name: str, payload: bytes) -> int:
        """A new vitals revision of `name`'s record now (`Membership.set_vitals`)."""
        i = self.index[name]
        core = self._call(i)
        set_vitals = getattr(core, "set_vitals", None)
        if set_vitals is None:
            raise TypeError(f"{type(core).__name__} has no vitals")
        revision: int = set_vitals(self.now, payload)
        self._drive(i, core, self.now)
        return revision

    def broadcast_event(self, name: str, kind: str, payload: bytes) -> None:
        """Let `name` broadcast a one-off event now."""
        i = self.index[name]
        core = self._call(i)
        core.broadcast_event(self.now, kind, payload)
        self._drive(i, core, self.now)

    def run_for(self, dt: float) -> None:
        """Advance the virtual clock by `dt` seconds."""
        self.run_until(self.now + dt)

    def run_until(self, t_end: float) -> None:
        """Process every datagram, timer and scheduled action due up to `t_end`."""
        heap, pop, up = self._heap, heapq.heappop, self._up
        cores: list[Any] = self._cores
        timer_at, last_fire, drive = self._timer_at, self._last_fire, self._drive
        while heap and heap[0][0] <= t_end:
            t, _, i, src, item = pop(heap)
            if src is not None:  # a datagram
                if up[i]:
                    self.now = t
                    core = cores[i]
                    core.receive(t, src, item)
                    drive(i, core, t)
            elif item is None:  # a timer: valid only if still the node's current deadline
                if t == timer_at[i] and up[i]:
                    self.now = t
                    if t == last_fire[i]:
                        self._spin(i)
                    else:
                        self._spins = 0
                    last_fire[i] = t
                    timer_at[i] = -1.0
                    core = cores[i]
                    core.handle_timer(t)
                    drive(i, core, t)
            else:
                self.now = t
                item()
        self.now = max(self.now, t_end)

    def wait_for(self, condition: Callable[[], bool], timeout: float, step: float = 0.05) -> bool:
        """Run in steps of `step` until `condition()` holds (True) or `timeout` passes (False)."""
        deadline = self.now + timeout
        while not condition():
            if self.now >= deadline:
                return False
            self.run_until(min(self.now + step, deadline))
        return True

    def converged(self) -> bool:
        """Whether every node has booted and each running one sees all the others alive."""
        return not self._unbooted and self.trace.all_alive(
            [i for i, up in enumerate(self._up) if up]
        )

    def converge(self, timeout: float, step: float = 0.05) -> float:
        """Run until converged; returns the virtual seconds it took, raises TimeoutError."""
        began = self.now
        if not self.wait_for(self.converged, timeout, step):
            up = [i for i, u in enumerate(self._up) if u]
            raise TimeoutError(f"not converged after {timeout} s: {self.trace.lagging(up)}")
        return self.now - began

    # -- internals ----------------------------------------------------------------------------

    def _call(self, i: int) -> Core:
        core = self._cores[i]
        if core is None or not self._up[i]:
            raise ValueError(f"{self.names[i]} is down")
        return core

    def _boot(self, i: int) -> None:
        name, addr = self.names[i], self.addrs[i]
        rng = random.Random(f"{self.seed}/{name}/{self._generation[i]}")
        core = self._factory(name, addr, self.config, self.now, rng)
        self._cores[i] = core
        self._up[i] = True
        self._unbooted.discard(i)
        self._timer_at[i] = math.inf
        self.trace.up(i, self.now)
        seeds = [self.addrs[s] for s in self._seeds if s != i and self._up[s]]
        if not seeds and i not in self._seeds:
            seeds = [self.addrs[j] for j, u in enumerate(self._up) if u and j != i][:1]
        core.join(self.now, seeds)
        self._drive(i, core, self.now)

    def _spin(self, i: int) -> None:
        self._spins += 1
        if self._spins > _MAX_SPINS:
            raise RuntimeError(
                f"{self.names[i]}: next_timer() stays at {self.now} after handle_timer()"
            )

    def _drive(self, i: int, core: Core, now: float) -> None:
        """Drain core i after a call: outbox onto the heap, events into the trace, its timer."""
        out = core.datagrams_to_send()
        if out:
            self.sent_datagrams[i] += len(out)
            size = self._size
            if size is not None:
                self.sent_bytes[i] += sum([size(p) for _, p in out])
            by_addr, verdict, heap, seq = self._by_addr, self.network.verdict, self._heap, self._seq
            src = self.addrs[i]
            for addr, packet in out:
                j = by_addr.get(addr)
                if j is None:
                    self.unroutable += 1
                    continue
                delay = verdict(i, j)
                if delay >= 0.0:
                    heapq.heappush(heap, (now + delay, next(seq), j, src, packet))
        event = core.next_event()
        if event is not None:
            record = self.trace.record
            while event is not None:
                record(i, event, now)
                event = core.next_event()
        deadline = core.next_timer()
        if deadline < now:  # noqa: PLR1730 - faster than max() on this path
            deadline = now
        if deadline != self._timer_at[i]:
            self._timer_at[i] = deadline
            if deadline != math.inf:
                heapq.heappush(self._heap, (deadline, next(self._seq), i, None, None))
