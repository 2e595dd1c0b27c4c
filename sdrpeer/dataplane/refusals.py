"""A dialing end's refusals, and which of them to tell: the first at once, then rate-limited.

How it works: a sending connection (or a service binding) whose receiver refuses it (an error
reply, a proof that does not hold, encryption refused) dials again, so it is refused again and
again. Its `DialRefusals` counts them, keeps the last reason and hands each to its `on_refused`
(None when a dial gets through after refusals): the host's report of them. Pure, time passed
in: `RefusalWatch.refused(now, conn, error)` is fed every refusal and returns a
`Told` when one is to be told: the first refusal of a connection at once, then at most one per
`every` seconds while they go on, carrying the latest error and how many refusals came since the
previous one told. `accepted(conn)` is fed when a connection got through: after refusals it
returns one `Told` with `error` None (the trouble is over), with the refusals not told yet.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass

__all__ = ["DialRefusals", "RefusalWatch", "Told"]

log = logging.getLogger("sdrpeer.dataplane")


@dataclass(frozen=True, slots=True)
class Told:
    """One refusal report of connection `conn`."""

    conn: str
    """The connection's id."""
    error: str | None
    """Why the receiver refused it (the latest refusal); None: it got through again."""
    count: int
    """Refusals since the previous report of this connection (the one told included)."""


class DialRefusals:
    """The refusals of one dialing end (a `Connection`, a `ServiceClient`)."""

    __slots__ = ("count", "last", "name", "on_refused")

    def __init__(self, name: str) -> None:
        self.name = name
        """The connection's id (for the log)."""
        self.count = 0
        """Dials the receiver refused."""
        self.last: str | None = None
        """Why the receiver refused the last dial (None once a dial got through)."""
        self.on_refused: Callable[[str | None], None] | None = None
        """Told every refusal's reason, and None when a dial gets through after refusals."""

    def refused(self, reason: str) -> None:
        """A dial was refused for `reason`."""
        self.count += 1
        self.last = reason
        self._tell(reason)

    def through(self) -> None:
        """A dial got through (told only after refusals)."""
        if self.last is not None:
            self.last = None
            self._tell(None)

    def _tell(self, reason: str | None) -> None:
        if self.on_refused is not None:
            try:
                self.on_refused(reason)
            except Exception:
                log.exception("data connection %s: on_refused failed", self.name)


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
