"""Which refusals of a sender's connections to tell: the first at once, then rate-limited.

How it works (pure; time is passed in): a sending connection whose receiver refuses it (an error
reply, a proof that does not hold, encryption refused) redials with backoff, so it is refused
again and again. `RefusalWatch.refused(now, conn, error)` is fed every refusal and returns a
`Told` when one is to be told: the first refusal of a connection at once, then at most one per
`every` seconds while they go on, carrying the latest error and how many refusals came since the
previous one told. `accepted(conn)` is fed when a connection got through: after refusals it
returns one `Told` with `error` None (the trouble is over), with the refusals not told yet.
"""

from __future__ import annotations

from dataclasses import dataclass

__all__ = ["RefusalWatch", "Told"]


@dataclass(frozen=True, slots=True)
class Told:
    """One refusal report of connection `conn`."""

    conn: str
    """The connection's id."""
    error: str | None
    """Why the receiver refused it (the latest refusal); None: it got through again."""
    count: int
    """Refusals since the previous report of this connection (the one told included)."""


class _Seen:
    __slots__ = ("told", "untold")

    def __init__(self) -> None:
        self.told: float | None = None  # when the last report went out
        self.untold = 0  # refusals since it


class RefusalWatch:
    """Refusal reports per connection, rate-limited."""

    def __init__(self, every: float = 30.0) -> None:
        self.every = every
        """Seconds between two reports about one connection while it keeps being refused."""
        self._seen: dict[str, _Seen] = {}

    def refused(self, now: float, conn: str, error: str) -> Told | None:
        """One more refusal of `conn`; the report to give now, if one is due."""
        seen = self._seen.setdefault(conn, _Seen())
        seen.untold += 1
        if seen.told is not None and now - seen.told < self.every:
            return None
        told = Told(conn, error, seen.untold)
        seen.told, seen.untold = now, 0
        return told

    def accepted(self, conn: str) -> Told | None:
        """`conn` got through: a report that its refusals are over, if it had any."""
        seen = self._seen.pop(conn, None)
        if seen is None:
            return None
        return Told(conn, None, seen.untold)

    def forget(self, conn: str) -> None:
        """`conn` is closed: nothing more to tell about it."""
        self._seen.pop(conn, None)
