"""What the election reads and publishes: `ElectionState`, `Candidate`, the rank, the encoding.

How it works:
- every robot publishes one `ElectionState` in its gossip record: the allocator it believes in
  (`leader`, at `epoch`) and whether it claims the role itself (`claiming`);
- gossip tells each robot about every other one; the caller turns that into one `Candidate` per
  robot (itself included): alive (membership ALIVE or SUSPECT), eligible (its metrics inside the
  allocation thresholds), configured priority, coarse health bucket and last published state;
- who *should* hold the role is decided by `rank(c) = (priority, health, name)`, highest first;
- which of two *claims* wins is decided by `claim_key = (epoch, name)`: it uses only what the
  claim itself carries, so every robot orders claims (and the plans they issue) the same way even
  while their views of priority and health differ;
- on the wire a state is the msgpack array `[epoch, leader|nil, claiming]`, the same layout as
  the `election` field of `sdrpeer.record.robot`; `state_to_wire`/`state_from_wire` give the array
  for embedding, `encode_state`/`decode_state` the standalone bytes.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import msgpack

from sdrpeer.errors import RecordError

MAX_EPOCH = 2**62
"""Largest epoch a decoder accepts (the record codec uses the same bound)."""

Rank = tuple[int, int, str]
"""(priority, health, name): the higher, the more a robot deserves the allocator role."""

ClaimKey = tuple[int, str]
"""(epoch, claimer): the higher claim wins; plans are fenced on the same order."""


@dataclass(frozen=True, slots=True)
class ElectionState:
    """What one robot publishes about the allocator role."""

    epoch: int
    """A claimer: the epoch of its claim. Anyone else: the highest epoch it has followed (usually
    its allocator's; higher when it followed a newer allocator that died, see `core.py`)."""
    leader: str | None
    """The allocator it believes in, or None while the role is vacant."""
    claiming: bool
    """True when this robot claims the role itself (then `leader` is its own name)."""


NO_STATE = ElectionState(0, None, False)
"""What a robot publishes before it knows anything."""


@dataclass(frozen=True, slots=True)
class Candidate:
    """One robot as gossip tells of it, built by the caller for every robot (itself included)."""

    alive: bool
    """Membership says ALIVE or SUSPECT (not DEAD, not LEFT)."""
    eligible: bool
    """Its battery, RSSI and link loss are inside the allocation thresholds, and it is not
    leaving; computed by the caller from the robot's record."""
    priority: int
    """Configured election priority (from its record): higher wins."""
    health: int
    """Coarse health bucket (`sdrpeer.election.health.health_bucket`): higher is healthier."""
    state: ElectionState | None
    """Its last published election state, None when its record has none yet."""


def rank(name: str, candidate: Candidate) -> Rank:
    """The order in which robots deserve the role: (priority, health, name), highest first."""
    return (candidate.priority, candidate.health, name)


def state_to_wire(state: ElectionState) -> list[Any]:
    """The msgpack-ready array `[epoch, leader|nil, claiming]`."""
    return [state.epoch, state.leader, state.claiming]


def state_from_wire(x: object) -> ElectionState:
    """Check and rebuild a state from its array; raises RecordError("malformed") on anything odd."""
    if not isinstance(x, list | tuple) or len(x) != 3:
        raise RecordError("malformed", "election: expected [epoch, leader, claiming]")
    epoch, leader, claiming = x
    if isinstance(epoch, bool) or not isinstance(epoch, int) or not 0 <= epoch <= MAX_EPOCH:
        raise RecordError("malformed", f"election.epoch: expected an int in [0, 2**62]: {epoch!r}")
    if leader is not None and not isinstance(leader, str):
        raise RecordError("malformed", "election.leader: expected a string or nil")
    if not isinstance(claiming, bool):
        raise RecordError("malformed", "election.claiming: expected a boolean")
    return ElectionState(epoch, leader, claiming)


def encode_state(state: ElectionState) -> bytes:
    """Standalone msgpack bytes of a state."""
    packed: bytes = msgpack.packb(state_to_wire(state), use_bin_type=True)
    return packed


def decode_state(data: bytes) -> ElectionState:
    """Inverse of `encode_state`; raises RecordError("malformed") on bad input, nothing else."""
    try:
        x = msgpack.unpackb(data, raw=False, strict_map_key=True)
    except Exception as e:  # msgpack raises several unrelated types
        raise RecordError("malformed", f"election: {type(e).__name__}") from None
    return state_from_wire(x)
