"""The robots a dashboard shows: the members view, plus the dead ones gossip has forgotten.

How it works (pure: the time is passed in): the membership protocol reaps a dead or departed
robot after a while (`dead_reap_time`), and from then on the members view no longer lists it, so
a robot that died would vanish from the page. `Roster.observe(now, members)` returns the members
view with `dead_since` set on every dead or departed member (the wall time its state began, from
the view's `since`, else the first time the roster saw it so) and, after them, the robots it saw
dead or departed that the view no longer lists: their last entry, marked `reaped`. A forgotten
robot is kept for `keep_s` after its death (the dashboard's window) and at most `max_kept` of
them; one that comes back is simply a member again. A robot that vanishes while alive (it was
never seen dead) is not kept: nothing says it died.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any

from sdrpeer.vocabulary import MemberState

__all__ = ["Roster"]

GONE = (MemberState.DEAD, MemberState.LEFT)
"""Member states after which a robot is kept once reaped."""


class Roster:
    """Members seen dead or departed, kept after gossip forgets them."""

    def __init__(self, keep_s: float = 900.0, max_kept: int = 256) -> None:
        self.keep_s = keep_s
        self.max_kept = max_kept
        self._gone: dict[str, dict[str, Any]] = {}
        """name -> its last entry while dead or departed (with `dead_since`)."""

    def observe(self, now: float, members: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
        """The members view with `dead_since` on the dead, then the reaped ones kept."""
        out: list[dict[str, Any]] = []
        listed = set()
        for m in members:
            name = str(m.get("name"))
            listed.add(name)
            if m.get("state") not in GONE:
                self._gone.pop(name, None)  # back (or never gone)
                out.append(dict(m))
                continue
            old = self._gone.get(name)
            since = m.get("since")
            if old is not None and old.get("state") == m.get("state"):
                dead_since = old["dead_since"]
            elif isinstance(since, int | float) and not isinstance(since, bool):
                dead_since = float(since)
            else:
                dead_since = now
            entry = {**m, "dead_since": dead_since}
            self._gone[name] = entry
            out.append(entry)
        for name, entry in list(self._gone.items()):
            if name in listed:
                continue
            if now - float(entry["dead_since"]) > self.keep_s:
                del self._gone[name]
                continue
            out.append({**entry, "reaped": True})
        self._bound()
        return out

    def _bound(self) -> None:
        """At most `max_kept` robots: the longest dead go first."""
        if len(self._gone) <= self.max_kept:
            return
        oldest = sorted(self._gone, key=lambda n: float(self._gone[n]["dead_since"]))
        for name in oldest[: len(self._gone) - self.max_kept]:
            del self._gone[name]

    def __len__(self) -> int:
        return len(self._gone)
