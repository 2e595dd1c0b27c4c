"""What the membership core reports to its shell: frozen dataclasses drained with `next_event()`."""

from __future__ import annotations

from dataclasses import dataclass

from sdrpeer.gossip.messages import Addr
from sdrpeer.vocabulary import MemberState


@dataclass(frozen=True, slots=True)
class MemberChanged:
    """A member was added or changed state (alive, suspect, dead, left) or was reaped.

    `state` is a MemberState, or REAPED (None) for reaped;
    `previous` is the prior state or None when the member is new.
    """

    name: str
    addr: Addr
    state: MemberState | None
    incarnation: int
    previous: MemberState | None
    at: float


@dataclass(frozen=True, slots=True)
class RecordChanged:
    """A newer version of a robot's record arrived (or our own was set)."""

    name: str
    version: int
    payload: bytes
    at: float


@dataclass(frozen=True, slots=True)
class VitalsChanged:
    """A newer vitals revision of a robot's record arrived (on a ping from that robot)."""

    name: str
    version: int
    revision: int
    payload: bytes
    at: float


@dataclass(frozen=True, slots=True)
class EventReceived:
    """A one-off broadcast (a trap, for instance) arrived for the first time."""

    source: str
    seq: int
    kind: str
    payload: bytes
    at: float


@dataclass(frozen=True, slots=True)
class ProbeOutcome:
    """A direct probe of `name` finished: rtt in seconds, or None when its ack never came."""

    name: str
    rtt: float | None
    at: float


CoreEvent = MemberChanged | RecordChanged | VitalsChanged | EventReceived | ProbeOutcome
REAPED = None
