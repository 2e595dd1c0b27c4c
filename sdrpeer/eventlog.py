"""A bounded, ordered log of what happened on and around this robot (the API's /v1/events)."""

from __future__ import annotations

from collections import Counter, deque
from collections.abc import Callable
from typing import Any


class EventLog:
    """Entries with increasing ids; the oldest fall off past `maxlen`."""

    def __init__(self, maxlen: int = 10_000) -> None:
        self._entries: deque[dict[str, Any]] = deque(maxlen=maxlen)
        self._next_id = 1
        self.listeners: list[Callable[[dict[str, Any]], None]] = []
        """Called with every new entry (the dashboard's live stream, the metrics' counters)."""
        self.counts: Counter[str] = Counter()
        """Entries ever added, by kind (not bounded by `maxlen`: Prometheus counters)."""

    def add(self, ts: float, kind: str, robot: str, **detail: Any) -> dict[str, Any]:
        """Append an entry and return it."""
        entry = {
            "id": self._next_id,
            "ts": round(ts, 3),
            "kind": kind,
            "robot": robot,
            "detail": detail,
        }
        self._next_id += 1
        self._entries.append(entry)
        self.counts[kind] += 1
        for listener in self.listeners:
            listener(entry)
        return entry

    def since(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        """Entries with id > since, oldest first, at most `limit`."""
        out: list[dict[str, Any]] = []
        if not self._entries or self._entries[-1]["id"] <= since:
            return out
        first = self._entries[0]["id"]
        start = max(0, since - first + 1)
        for i in range(start, len(self._entries)):
            out.append(self._entries[i])
            if len(out) >= limit:
                break
        return out

    def __len__(self) -> int:
        return len(self._entries)


class RecoveryTally:
    """Recovery steps by action and components moved, counted from the event log as it grows
    (`count` is a listener), so Prometheus counters survive the log's bound."""

    def __init__(self) -> None:
        self.actions: Counter[str] = Counter()
        self.moves: Counter[str] = Counter()

    def count(self, entry: dict[str, Any]) -> None:
        """Count one entry if it is a recovery decision or move."""
        detail = entry["detail"]
        if entry["kind"] == "recovery.decision":
            self.actions[str(detail.get("action"))] += 1
        elif entry["kind"] == "recovery.move":
            for component in detail.get("moved") or {}:
                self.moves[str(component)] += 1
