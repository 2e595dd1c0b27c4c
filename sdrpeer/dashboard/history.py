"""A bounded history of every robot's metrics, so a dashboard opened late still shows the past.

How it works (pure: the time is passed in): `add(ts, members)` turns the agent's members view into
one compact frame — per robot its free memory, CPU, battery, RSSI and the typical RTT, jitter and
loss of the links it measures (its record's link summary: the values a strict majority of its links
reach; per-pair link series would grow with the square of the fleet) — stored as one `array('f')`
per frame, so 15 minutes of a 50-robot fleet at one frame a second take about 1.5 MB. Frames older
than `window_s` fall off; so does the oldest frame past `max_frames`. `series(since)` is the
columnar JSON the dashboard plots: times, and per robot one list per metric (None where a robot did
not report).
"""

from __future__ import annotations

import math
from array import array
from collections import deque
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from sdrpeer.vocabulary import MemberState

__all__ = ["METRICS", "History", "frame_values", "typical_link"]

METRICS: Final = ("mem_free", "cpu_pct", "battery_pct", "rssi_dbm", "rtt_ms", "jitter_ms", "loss")
"""The series kept per robot, in frame order."""
_NAN: Final = float("nan")


@dataclass(frozen=True, slots=True)
class _Frame:
    ts: float
    robots: tuple[str, ...]
    """The robots of `values`, in order (shared between frames while the fleet is unchanged)."""
    values: array[float]
    """len(robots) * len(METRICS) values, NaN where unknown."""


def _number(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return _NAN
    return float(value)


def frame_values(member: Mapping[str, Any]) -> list[float]:
    """The METRICS of one member of the members view (NaN where unknown)."""
    metrics = member.get("metrics") or {}
    typical = typical_link(member)
    return [
        _number(metrics.get("mem_free")),
        _number(metrics.get("cpu_pct")),
        _number(metrics.get("battery_pct")),
        _number(metrics.get("rssi_dbm")),
        _number(typical.get("rtt_ms")),
        _number(typical.get("jitter_ms")),
        _number(typical.get("loss")),
    ]


def typical_link(member: Mapping[str, Any]) -> Mapping[str, Any]:
    """The typical link of a member of the members view ({} when it measured none)."""
    summary = member.get("link_summary")
    typical = summary.get("typical") if isinstance(summary, Mapping) else None
    return typical if isinstance(typical, Mapping) else {}


class History:
    """Frames of the fleet's metrics over the last `window_s` seconds."""

    def __init__(self, window_s: float = 900.0, max_frames: int = 3600) -> None:
        self.window_s = window_s
        self._frames: deque[_Frame] = deque(maxlen=max_frames)
        self._robots: tuple[str, ...] = ()

    def __len__(self) -> int:
        return len(self._frames)

    def add(self, ts: float, members: Iterable[Mapping[str, Any]]) -> None:
        """Record the alive and suspect members' metrics at `ts` (seconds, increasing)."""
        rows = [m for m in members if m.get("state") in (MemberState.ALIVE, MemberState.SUSPECT)]
        names = tuple(str(m.get("name")) for m in rows)
        if names != self._robots:
            self._robots = names  # a new tuple only when the fleet changes
        values = array("f")
        for m in rows:
            values.extend(frame_values(m))
        self._frames.append(_Frame(ts, self._robots, values))
        while self._frames and self._frames[0].ts < ts - self.window_s:
            self._frames.popleft()

    def series(self, since: float = float("-inf")) -> dict[str, Any]:
        """{"t": [ts, ...], "robots": {name: {metric: [value|None, ...]}}} for frames after
        `since` (every robot seen in them; None where it did not report)."""
        frames = [f for f in self._frames if f.ts > since]
        robots: dict[str, dict[str, list[float | None]]] = {}
        for k, frame in enumerate(frames):
            width = len(METRICS)
            for r, name in enumerate(frame.robots):
                lists = robots.get(name)
                if lists is None:
                    lists = robots[name] = {m: [None] * k for m in METRICS}
                for j, metric in enumerate(METRICS):
                    x = frame.values[r * width + j]
                    lists[metric].append(None if math.isnan(x) else round(x, 3))
            for lists in robots.values():
                if len(lists[METRICS[0]]) == k:  # not in this frame
                    for metric in METRICS:
                        lists[metric].append(None)
        return {"t": [round(f.ts, 3) for f in frames], "robots": robots}

    def bytes_used(self) -> int:
        """Approximate bytes held by the frames' values (for the history bound's tests)."""
        return sum(f.values.itemsize * len(f.values) for f in self._frames)
