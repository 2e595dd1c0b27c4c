"""What the election core reports to its caller: frozen dataclasses drained with `next_event()`."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Elected:
    """This robot claimed the allocator role at `epoch` (also when it re-claims at a higher
    epoch to get past one it heard of: `previous` is then its former epoch)."""

    epoch: int
    previous: int | None
    at: float


@dataclass(frozen=True, slots=True)
class SteppedDown:
    """This robot gave the role up: `reason` is "outranked" (a higher claim), "ineligible" or
    "left" (it abdicated)."""

    epoch: int
    reason: str
    at: float


@dataclass(frozen=True, slots=True)
class LeaderChanged:
    """The allocator this robot believes in changed: `leader` None means the role is vacant."""

    epoch: int
    leader: str | None
    previous: str | None
    at: float


ElectionEvent = Elected | SteppedDown | LeaderChanged
