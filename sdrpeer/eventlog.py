"""A bounded, ordered log of what happened on and around this robot (the API's /v1/events),
and the kinds of its entries (`EventKind`)."""

from __future__ import annotations

import json
import re
from collections import Counter, deque
from collections.abc import Callable, Iterable, Mapping
from enum import StrEnum
from typing import Any


class EventKind(StrEnum):
    """Every kind of entry the event log holds, declared once: producers and consumers name
    these members, never the strings (tests/test_event_kinds.py holds the code to it)."""

    AGENT_START = "agent.start"
    """This agent started (its addresses, preset)."""
    SCENARIO = "scenario"
    """A virtual robot's scenario step changed its facts."""
    ROBOT_SET = "robot.set"
    """A virtual robot's facts were changed through the API."""
    TRAP = "trap"
    """A threshold crossing (battery, RSSI: broadcast; memory, CPU: this robot's)."""
    TRAP_MALFORMED = "trap.malformed"
    """A peer's trap did not decode."""
    RECORD_MALFORMED = "record.malformed"
    """A peer's record did not decode."""
    VITALS_MALFORMED = "vitals.malformed"
    """A peer's vitals did not decode."""
    WIRE_REJECTED = "wire.rejected"
    """Gossip datagrams refused (rate-limited summary by reason)."""
    KEYS_RELOADED = "keys.reloaded"
    """The key file was read again and its keys are in use."""
    KEYS_RELOAD_FAILED = "keys.reload_failed"
    """The key file could not be read: the old keys stay."""
    MEMBER_JOIN = "member.join"
    """A robot was heard of for the first time."""
    MEMBER_ALIVE = "member.alive"
    """A robot is alive again."""
    MEMBER_SUSPECT = "member.suspect"
    """A robot is suspected of having failed."""
    MEMBER_DEAD = "member.dead"
    """A robot was declared dead."""
    MEMBER_LEFT = "member.left"
    """A robot left the fleet."""
    MEMBER_REAPED = "member.reaped"
    """A dead or departed robot was forgotten."""
    INSTANCE_STATE = "instance.state"
    """An instance on this robot changed state."""
    INSTANCE_FAULT = "instance.fault"
    """A component fault, an instance in ERROR or a host that died."""
    ELECTION = "election"
    """The allocator this robot believes in changed (epoch, leader)."""
    ELECTION_ELECTED = "election.elected"
    """This robot claimed the allocator role."""
    ELECTION_STEPPED_DOWN = "election.stepped_down"
    """This robot gave the allocator role up."""
    PLAN_ACCEPTED = "plan.accepted"
    """This robot took a newer plan."""
    PLAN_REFUSED = "plan.refused"
    """A plan from a fenced-off epoch was refused."""
    PLAN_SUPERSEDED = "plan.superseded"
    """An active here stood down for a newer plan's copy elsewhere."""
    LAUNCH_REFUSED = "launch.refused"
    """A placement here is one this robot's launch policy refuses."""
    ALLOCATION = "allocation"
    """The allocator issued a plan (deploy, re-allocation, move)."""
    ALLOCATION_INFEASIBLE = "allocation.infeasible"
    """No placement meets the constraints."""
    RECONCILE = "reconcile"
    """A component goes back to its original robot (keep_original)."""
    MOVE = "move"
    """A planned move."""
    RECOVERY_MOVE = "recovery.move"
    """The allocator moved components off a failing robot."""
    RECOVERY_DECISION = "recovery.decision"
    """Local recovery chose a step of the ladder."""
    RECOVERY_EXHAUSTED = "recovery.exhausted"
    """Local recovery ran out of steps."""
    RECOVERY_CONDITION = "recovery.condition"
    """A robot-wide recovery condition holds."""
    RECOVERY_CLEARED = "recovery.cleared"
    """A robot-wide recovery condition no longer holds."""
    COMPLIANCE_VIOLATED = "compliance.violated"
    """A running placement has failed one of its Table I/II constraints for the sustain time
    (this robot's judgement: component, constraint, value, bound, robots)."""
    COMPLIANCE_CLEARED = "compliance.cleared"
    """A violated constraint is inside its bound again past the hysteresis margin, or the
    placement it was about changed."""
    COMPLIANCE_MOVE = "compliance.move"
    """The allocator moved a component whose placement violated a constraint
    (`compliance.on_violation: replace`)."""
    FLEET_CUT_OFF = "fleet.cut_off"
    """This robot hears fewer than a majority of the fleet."""
    FLEET_REJOINED = "fleet.rejoined"
    """This robot hears a majority again and is catching up."""
    FLEET_IN_TOUCH = "fleet.in_touch"
    """This robot is in touch with the fleet."""
    CONN_REFUSED = "conn.refused"
    """A receiver refuses an outgoing connection of an instance here (its reason; the host says
    the first refusal at once, then at most one per connection every 30 s while it goes on)."""
    CONN_ACCEPTED = "conn.accepted"
    """A connection refused before got through to its receiver."""
    PORT_OVERFLOW = "port.overflow"
    """An instance's connections started losing frames to full buffers (sdrpeer.runtime.overflow);
    then at most one per port every 30 s while it goes on."""
    STATE_HANDOFF = "state.handoff"
    """A component's state was sent to another instance."""
    STATE_RESTORED = "state.restored"
    """A component's state was restored here."""
    STATE_DROPPED = "state.dropped"
    """A state that arrived here was dropped."""
    STATE_FAILED = "state.failed"
    """A state handoff failed."""


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


def naming(names: Iterable[str]) -> Callable[[Mapping[str, Any]], bool]:
    """A test of whether an entry names any of `names` as a whole word: as its robot, or
    anywhere in its detail (`CamA` names neither `CamA-s1` nor `x.CamA2`)."""
    words = [n for n in names if n]
    alternatives = "|".join(re.escape(n) for n in words)
    pattern = re.compile(r"(?<![\w.-])(?:" + alternatives + r")(?![\w-])")

    def names_it(entry: Mapping[str, Any]) -> bool:
        if not words:
            return False
        if str(entry.get("robot", "")) in words:
            return True
        return bool(pattern.search(json.dumps(entry.get("detail", {}), sort_keys=True)))

    return names_it


class RecoveryTally:
    """Recovery steps by action and components moved, counted from the event log as it grows
    (`count` is a listener), so Prometheus counters survive the log's bound."""

    def __init__(self) -> None:
        self.actions: Counter[str] = Counter()
        self.moves: Counter[str] = Counter()

    def count(self, entry: dict[str, Any]) -> None:
        """Count one entry if it is a recovery decision or move."""
        detail = entry["detail"]
        if entry["kind"] == EventKind.RECOVERY_DECISION:
            self.actions[str(detail.get("action"))] += 1
        elif entry["kind"] == EventKind.RECOVERY_MOVE:
            for component in detail.get("moved") or {}:
                self.moves[str(component)] += 1
