"""Questions asked of a recorded timeline: the demo's figures of merit (pure, no I/O).

How it works: `Timeline` holds the lines (sdrpeer/demo/timeline.py writes them; `load_timeline`
reads them back) sorted by `t` and answers by scanning them in order: the first line of a kind
that matches, when a set of components first all had an active instance (replaying the "state"
lines), when a robot's RSSI first fell to a threshold. A match value may be a plain value
(equality) or a predicate, e.g. `first("event", event=lambda k: k.startswith("recovery."))`.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Iterator
from typing import Any

from sdrpeer.record.robot import state_to_wire
from sdrpeer.vocabulary import InstanceRole, LifecycleState

Line = dict[str, Any]


def _matches(line: Line, match: dict[str, Any]) -> bool:
    for key, want in match.items():
        have = line.get(key)
        if callable(want):
            if not want(have):
                return False
        elif have != want:
            return False
    return True


class Timeline:
    """A recorded timeline in time order, with the helpers the demo's report needs."""

    def __init__(self, lines: Iterable[Line]) -> None:
        self.lines = sorted(lines, key=lambda line: float(line.get("t", 0.0)))

    def of(self, kind: str, *, after: float = float("-inf"), **match: Any) -> Iterator[Line]:
        """Lines of `kind` at t >= after whose fields match (values or predicates)."""
        for line in self.lines:
            if line.get("kind") == kind and line["t"] >= after and _matches(line, match):
                yield line

    def first(self, kind: str, *, after: float = float("-inf"), **match: Any) -> Line | None:
        """The first line of `kind` at t >= after whose fields match, or None."""
        return next(self.of(kind, after=after, **match), None)

    def marks(self, what: str) -> list[float]:
        """When marks of `what` (allocation, recovery, fault) were added."""
        return [line["t"] for line in self.of("mark", what=what)]

    def robots(self) -> list[str]:
        """The robots the recorder polled (its start line), else those with samples."""
        start = self.first("start")
        if start is not None and isinstance(start.get("robots"), list):
            return [str(r) for r in start["robots"]]
        return sorted({str(line["robot"]) for line in self.of("sample")})

    def when_all_active(
        self, components: Collection[str], after: float = 0.0, *, exclude: Collection[str] = ()
    ) -> float | None:
        """First t >= after at which each component has an ACTIVE instance in the active role.

        Instances on the robots in `exclude` do not count (e.g. the robot recovery moves away
        from). When the condition already holds at `after`, the answer is `after`.
        """
        wanted = set(components)
        running: dict[tuple[str, str], str] = {}  # (robot, instance) -> component, when active
        for line in self.lines:
            if line["t"] > after and wanted <= set(running.values()):
                return after
            if line.get("kind") != "state":
                continue
            key = (str(line.get("robot")), str(line.get("instance")))
            active = (
                line.get("state") == state_to_wire(LifecycleState.ACTIVE)
                and line.get("role", InstanceRole.ACTIVE) == InstanceRole.ACTIVE
            )
            if active and key[0] not in exclude:
                running[key] = str(line.get("component"))
            else:
                running.pop(key, None)
            if line["t"] >= after and wanted <= set(running.values()):
                return float(line["t"])
        if wanted <= set(running.values()):
            return after
        return None

    def rssi_crossing(
        self, robot: str, threshold: float, after: float = float("-inf")
    ) -> float | None:
        """First t >= after of a sample of `robot` with RSSI at or below `threshold` dBm."""

        def below(rssi: Any) -> bool:
            return isinstance(rssi, int | float) and rssi <= threshold

        line = self.first("sample", after=after, robot=robot, rssi=below)
        return None if line is None else float(line["t"])
