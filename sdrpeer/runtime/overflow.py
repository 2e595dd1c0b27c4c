"""Which connections started losing frames to full buffers: the warnings the agent logs.

How it works (pure; time is passed in): `OverflowWatch.feed(now, instance, ports)` takes one
instance's port counters from its heartbeat. An OutPort's `overflowed` counter adds up what its
connections lost because a buffer was full at either end (the sender's queue, and what the
receiving InPort's acknowledgements reported); what `push: new` replaces and `push: skip` thins
out is the policy's purpose and not counted there. The first increase after a quiet spell is
warned about at once; while it goes on, at most one warning per `every` seconds, with the frames
lost since the last one. Counters that go down belong to a new host process: counted afresh.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass

__all__ = ["Overflow", "OverflowWatch"]


@dataclass(frozen=True, slots=True)
class Overflow:
    """One warning: `frames` lost on `instance`'s OutPort `port` since the last warning."""

    instance: str
    port: str
    frames: int
    total: int
    """Lost by this port since its host started."""


class _Seen:
    __slots__ = ("pending", "total", "warned")

    def __init__(self, total: int) -> None:
        self.total = total
        self.pending = 0  # lost since the last warning
        self.warned: float | None = None  # when the last warning went out


class OverflowWatch:
    """Overflow warnings per (instance, OutPort), rate-limited."""

    def __init__(self, every: float = 30.0) -> None:
        self.every = every
        """Seconds between two warnings about one port while it keeps losing frames."""
        self._seen: dict[tuple[str, str], _Seen] = {}

    def feed(
        self, now: float, instance: str, ports: Mapping[str, Mapping[str, int]]
    ) -> list[Overflow]:
        """The warnings due after `instance`'s latest port counters."""
        out = []
        for port, counters in ports.items():
            total = int(counters.get("overflowed", 0))
            key = (instance, port)
            seen = self._seen.get(key)
            if seen is None:
                seen = self._seen[key] = _Seen(0)
            if total < seen.total:  # a new host process: its counters began again
                seen.total = 0
            seen.pending += total - seen.total
            seen.total = total
            quiet = seen.warned is None or now - seen.warned >= self.every
            if seen.pending > 0 and quiet:
                out.append(Overflow(instance, port, seen.pending, total))
                seen.pending = 0
                seen.warned = now
        return out

    def keep(self, instances: Collection[str]) -> None:
        """Forget every instance not among `instances` (the ones gone)."""
        for key in [k for k in self._seen if k[0] not in instances]:
            del self._seen[key]
