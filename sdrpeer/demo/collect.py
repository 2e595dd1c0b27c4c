"""What the agents answer, turned into timeline lines (pure: no clock, no I/O).

How it works: every poll round the recorder asks each agent for `/v1/members` and its new
`/v1/events` (ids above `cursor(agent)`) and hands the answers, each with the wall-clock time it
came back, to `Collector.round`, which returns the JSON lines to write. `t` is seconds since
`start` (wall clock): `answer.at - start` for what was polled, `event.ts - start` for events.

- "agent": an agent started or stopped answering (only on change; the error says why).
- "sample": each robot's metrics as its OWN agent shows them; none while that agent is silent.
- "state": an instance's (component, role, state) changed, or it is "gone". Every agent lists
  every robot, so each robot's instances are taken from its own agent when it answers, else
  from the first other answering agent that knows its record (`via` says which). A robot that
  view holds dead or left, or that no answering agent lists any more, hosts nothing.
- "event": the kinds `wanted()` keeps. From each agent only its own events (`robot` == the
  agent), except `member.*`, which come from one agent at a time (the one already used while it
  answers, else the first that answers) and only when newer than the last member event kept, so
  two agents' views of one death are not both kept. An agent that failed to answer is re-read
  from id 0 (it may have restarted with fresh ids); the key (robot, kind, ts, agent) drops an
  entry read twice.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from sdrpeer.eventlog import EventKind
from sdrpeer.vocabulary import MemberState

EVENT_KINDS = frozenset(
    {
        EventKind.ELECTION,
        EventKind.ALLOCATION,
        EventKind.PLAN_ACCEPTED,
        EventKind.TRAP,
        EventKind.SCENARIO,
        EventKind.ROBOT_SET,
        EventKind.MEMBER_DEAD,
        EventKind.MEMBER_SUSPECT,
        EventKind.MEMBER_LEFT,
        EventKind.MEMBER_ALIVE,
    }
)
"""Event kinds the timeline keeps, besides every `recovery.*`."""
GONE = "gone"
"""The state of an instance that is no longer listed on its robot."""

Line = dict[str, Any]
Views = Mapping[str, Mapping[str, dict[str, Any]]]
"""Per answering agent: its members by name."""


def wanted(kind: str) -> bool:
    """True for the event kinds the timeline keeps."""
    return kind in EVENT_KINDS or kind.startswith("recovery.")


@dataclass(frozen=True, slots=True)
class Answer:
    """What one agent answered in one round."""

    agent: str
    """The robot whose agent was asked (its name as it calls itself)."""
    at: float
    """Wall-clock time the answer came back."""
    members: list[dict[str, Any]] | None = None
    """`/v1/members`; None when the agent did not answer."""
    events: list[dict[str, Any]] = field(default_factory=list)
    """The new `/v1/events` entries, oldest first."""
    error: str | None = None
    """Why the agent did not answer."""


class Collector:
    """Keeps what was already written (states, events, agents up) and makes the new lines."""

    def __init__(self, agents: Sequence[str], start: float) -> None:
        self.agents = list(agents)
        self.start = start
        self._cursor = dict.fromkeys(self.agents, 0)
        self._up: dict[str, bool] = {}
        self._states: dict[tuple[str, str], tuple[Any, Any, Any]] = {}
        self._seen: set[tuple[str, str, float, str]] = set()
        self._member_source: str | None = None
        self._member_mark = float("-inf")

    def cursor(self, agent: str) -> int:
        """The highest event id already read from `agent` (ask for events after it)."""
        return self._cursor.get(agent, 0)

    def _t(self, wall: float) -> float:
        return round(wall - self.start, 3) + 0.0  # never -0.0

    def round(self, answers: Sequence[Answer]) -> list[Line]:
        """The lines one poll round adds, given every agent's answer (or failure)."""
        lines: list[Line] = []
        for a in answers:
            lines.extend(self._health(a))
        ok = [a for a in answers if a.members is not None]
        views = {a.agent: _by_name(a.members or []) for a in ok}
        for a in ok:
            lines.extend(self._sample(a, views[a.agent]))
        lines.extend(self._events(ok))
        at = max((a.at for a in answers), default=self.start)
        lines.extend(self._state_lines(views, at))
        return lines

    def _health(self, a: Answer) -> list[Line]:
        up = a.members is not None
        if not up:
            self._cursor[a.agent] = 0
        if self._up.get(a.agent) == up:
            return []
        self._up[a.agent] = up
        status = "up" if up else "down"
        return [
            {"t": self._t(a.at), "kind": "agent", "robot": a.agent, "status": status}
            | ({} if up else {"error": a.error or "no answer"})
        ]

    def _sample(self, a: Answer, view: Mapping[str, dict[str, Any]]) -> list[Line]:
        metrics = view.get(a.agent, {}).get("metrics")
        if not isinstance(metrics, dict):
            return []
        return [
            {
                "t": self._t(a.at),
                "kind": "sample",
                "robot": a.agent,
                "mem_free": metrics.get("mem_free"),
                "mem_total": metrics.get("mem_total"),
                "cpu": metrics.get("cpu_pct"),
                "battery": metrics.get("battery_pct"),
                "rssi": metrics.get("rssi_dbm"),
            }
        ]

    def _events(self, ok: Sequence[Answer]) -> list[Line]:
        names = [a.agent for a in ok]
        if self._member_source not in names:
            self._member_source = names[0] if names else None
        lines: list[Line] = []
        for a in ok:
            for e in a.events:
                line = self._event(a.agent, e)
                if line is not None:
                    lines.append(line)
        return lines

    def _event(self, agent: str, e: dict[str, Any]) -> Line | None:
        eid, ts, kind, robot = e.get("id"), e.get("ts"), e.get("kind"), e.get("robot")
        if isinstance(eid, int):
            self._cursor[agent] = max(self._cursor.get(agent, 0), eid)
        if not (isinstance(ts, int | float) and isinstance(kind, str) and isinstance(robot, str)):
            return None
        if not wanted(kind):
            return None
        if kind.startswith("member."):
            if agent != self._member_source or ts <= self._member_mark:
                return None
            self._member_mark = ts
        elif robot != agent:
            return None
        key = (robot, kind, float(ts), agent)
        if key in self._seen:
            return None
        self._seen.add(key)
        detail = e.get("detail")
        return {
            "t": self._t(ts),
            "kind": "event",
            "robot": robot,
            "event": kind,
            "detail": detail if isinstance(detail, dict) else {},
            "via": agent,
        }

    def _state_lines(self, views: Views, at: float) -> list[Line]:
        if not views:
            return []
        robots = list(self.agents)
        for view in views.values():
            robots.extend(r for r in view if r not in robots)
        robots.extend(r for r, _ in self._states if r not in robots)
        lines: list[Line] = []
        for robot in robots:
            found = self._instances_of(robot, views)
            if found is None:
                continue
            via, instances = found
            now: dict[tuple[str, str], tuple[Any, Any, Any]] = {}
            for i in instances:
                if isinstance(i, dict) and isinstance(i.get("name"), str):
                    now[(robot, i["name"])] = (i.get("component"), i.get("role"), i.get("state"))
            for key in [k for k in self._states if k[0] == robot and k not in now]:
                component, role, _ = self._states.pop(key)
                lines.append(self._state_line(at, key, (component, role, GONE), via))
            for key, value in now.items():
                if self._states.get(key) != value:
                    self._states[key] = value
                    lines.append(self._state_line(at, key, value, via))
        return lines

    def _state_line(
        self, at: float, key: tuple[str, str], value: tuple[Any, Any, Any], via: str | None
    ) -> Line:
        component, role, state = value
        return {
            "t": self._t(at),
            "kind": "state",
            "robot": key[0],
            "instance": key[1],
            "component": component,
            "role": role,
            "state": state,
            "via": via,
        }

    def _instances_of(self, robot: str, views: Views) -> tuple[str | None, list[Any]] | None:
        """(which agent's view, the robot's instances); None when no answering view can tell."""
        own = views.get(robot, {}).get(robot)
        if own is not None:
            return robot, list(own.get("instances") or [])
        others = [a for a in self.agents if a in views] + sorted(set(views) - set(self.agents))
        for agent in others:
            member = views[agent].get(robot)
            if member is None:
                continue
            if member.get("state") in (MemberState.DEAD, MemberState.LEFT):
                return agent, []
            if member.get("metrics") is None:
                continue
            return agent, list(member.get("instances") or [])
        if any(r == robot for r, _ in self._states) and all(robot not in v for v in views.values()):
            return None, []
        return None


def _by_name(members: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    return {m["name"]: m for m in members if isinstance(m, dict) and isinstance(m.get("name"), str)}
