"""Gossip messages: frozen, slotted dataclasses. The codec for them lives in `sdrpeer.gossip.wire`.

Two layers:
- *updates* are facts that spread epidemically (piggybacked on any packet): a member is alive,
  suspect or dead; a robot's record changed; a one-off event (a trap) happened;
- *packets* are what one datagram carries: a probe, its acks, a gossip round, a sync chunk or
  digest. Every packet names its sender and carries a tuple of piggybacked updates.

A ping may also carry the sender's `VitalsRevision`: the newest revision of the measured part of
its record, sent directly to the robot probed (until it acknowledges one as new), never spread.

Every packet also names its *receiver*, `to`: the robot it is addressed to, which the codec binds
the sealed datagram to (sdrpeer.gossip.wire), so a datagram replayed to another robot does not
open there. A ping's receiver is its target. `to == ""` addresses whoever listens at the
destination address: only what a robot sends to an address whose robot it does not know yet (a
seed it joins by address); such a datagram carries no piggybacked update and proves no life.
A decoded packet's `to` is the receiving robot's name when it was bound to it, else "".
"""

from __future__ import annotations

from dataclasses import dataclass

from sdrpeer.vocabulary import MemberState

Addr = tuple[str, int]
"""A UDP address: (host, port)."""

# Member states (sdrpeer.vocabulary) by the short names the gossip code uses; small ints on the
# wire (sdrpeer.gossip.wire).
ALIVE, SUSPECT, DEAD, LEFT = (
    MemberState.ALIVE,
    MemberState.SUSPECT,
    MemberState.DEAD,
    MemberState.LEFT,
)


@dataclass(frozen=True, slots=True)
class Alive:
    """`name` is alive at `addr` with `incarnation` (a refutation raises the incarnation)."""

    name: str
    addr: Addr
    incarnation: int


@dataclass(frozen=True, slots=True)
class Suspect:
    """`source` suspects `name` at `incarnation` (its probes failed)."""

    name: str
    incarnation: int
    source: str


@dataclass(frozen=True, slots=True)
class Dead:
    """`source` declares `name` dead at `incarnation`; source == name means a graceful leave."""

    name: str
    incarnation: int
    source: str


@dataclass(frozen=True, slots=True)
class Record:
    """The versioned record owned by robot `name` (opaque bytes to gossip; see
    `sdrpeer.record.robot`)."""

    name: str
    version: int
    payload: bytes


@dataclass(frozen=True, slots=True)
class Event:
    """A one-off broadcast from `source` (a trap, for instance), unique by (source, seq)."""

    source: str
    seq: int
    kind: str
    payload: bytes


Update = Alive | Suspect | Dead | Record | Event


@dataclass(frozen=True, slots=True)
class VitalsRevision:
    """Revision `revision` (1, 2, ...) of the measured part of record `version` of the sender
    (opaque bytes to gossip; see `sdrpeer.record.robot`). Ordered by (version, revision)."""

    version: int
    revision: int
    payload: bytes

    @property
    def key(self) -> tuple[int, int]:
        """Its order: a newer record version, then a higher revision, wins."""
        return (self.version, self.revision)


@dataclass(frozen=True, slots=True)
class Ping:
    """Direct probe of `target` by `sender`; answered with an Ack of the same seq."""

    sender: str
    seq: int
    target: str
    updates: tuple[Update, ...] = ()
    vitals: VitalsRevision | None = None

    @property
    def to(self) -> str:
        """The robot this ping is addressed to: its target."""
        return self.target


@dataclass(frozen=True, slots=True)
class PingReq:
    """`sender` asks the receiver to probe `target` at `target_addr` on its behalf."""

    sender: str
    seq: int
    target: str
    target_addr: Addr
    want_nack: bool
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


@dataclass(frozen=True, slots=True)
class Ack:
    """Answer to a Ping (or a forwarded answer to a PingReq) with the probe's seq."""

    sender: str
    seq: int
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


@dataclass(frozen=True, slots=True)
class Nack:
    """An intermediary could not reach the target of a PingReq in time (Lifeguard)."""

    sender: str
    seq: int
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


@dataclass(frozen=True, slots=True)
class Gossip:
    """A gossip round: nothing but piggybacked updates."""

    sender: str
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


SyncEntry = tuple[str, Addr, int, MemberState, int]
"""One member in a sync digest: (name, addr, incarnation, state, record_version)."""


@dataclass(frozen=True, slots=True)
class Sync:
    """One self-contained chunk of a full-state exchange (anti-entropy).

    `reply` asks the receiver to answer with its own full state. Each chunk merges on its own, so
    a lost chunk costs only its entries, never the exchange.
    """

    sender: str
    reply: bool
    entries: tuple[SyncEntry, ...]
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


@dataclass(frozen=True, slots=True)
class Digest:
    """The digest of the sender's member table (anti-entropy's cheap first step): a receiver
    whose own digest differs answers with its full state (a `Sync` asking for a reply)."""

    sender: str
    digest: int
    count: int
    """Members alive or suspect in the digest (shown in logs; not compared)."""
    updates: tuple[Update, ...] = ()
    to: str = ""
    """The robot this packet is addressed to ("": whoever listens at the address)."""


Packet = Ping | PingReq | Ack | Nack | Gossip | Sync | Digest
