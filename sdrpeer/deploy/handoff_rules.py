"""State handoff between instances of one component: who sends a state where, who takes it.

How it works (pure: the plan and `now` are passed in):
- **sync**: an instance that is its component's active placement on this robot, ACTIVE, with
  `standby.sync` > 0 in the system, hands its `on_snapshot()` every `sync` seconds to each hot
  standby of the component (`SyncSchedule.due`). A standby that takes over after a crash or a
  robot's death so continues from at most `sync` ago.
- **final**: an ACTIVE instance about to be stopped because the plan moved its component to
  another instance (recovery, a same-robot swap, a re-allocation) hands its last snapshot to the
  component's new active instance (`final_target`). A planned move so loses no state.
- **admission** (`admit`, on the receiving robot, against its own plan): a sync is taken only by
  an instance that is a standby here and only from the component's active instance — a robot
  still running an old active on the far side of a partition cannot roll a new active back; a
  final is taken only by the component's active instance here. A final for a plan newer than
  ours is held (the plan is on its way); so is any state for an instance not yet running.
Every message names the plan it was sent under (its key) so the receiver can tell which is behind.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any, Final

import msgpack

from sdrpeer.plan import Placement, Plan
from sdrpeer.vocabulary import InstanceRole

__all__ = [
    "KINDS",
    "Send",
    "StateMsg",
    "SyncSchedule",
    "admit",
    "final_target",
    "sync_targets",
]

KINDS: Final = ("sync", "final")
APPLY: Final = "apply"
HOLD: Final = "hold"


@dataclass(frozen=True, slots=True)
class StateMsg:
    """One state on its way from one instance to another."""

    kind: str
    """sync (periodic, to a hot standby) or final (a planned move, to the new active)."""
    component: str
    source: str
    """The instance the state was taken from."""
    target: str
    """The instance it is for."""
    plan: tuple[int, str, int]
    """The key of the plan the sender held."""
    state: Any
    """The value of the source's on_snapshot."""
    origin: str = ""
    """The robot the source ran on ("" when unknown: a sender of an older version)."""

    def encode(self) -> bytes:
        """msgpack form (`decode` inverts it)."""
        doc = [self.kind, self.component, self.source, self.target, list(self.plan), self.state]
        if self.origin:
            doc.append(self.origin)
        blob: bytes = msgpack.packb(doc, use_bin_type=True)
        return blob

    @classmethod
    def decode(cls, blob: bytes) -> StateMsg:
        """Rebuild a message; ValueError naming what is wrong (peers may be buggy or hostile)."""
        try:
            doc = msgpack.unpackb(blob, raw=False, strict_map_key=False)
        except (ValueError, msgpack.UnpackException) as exc:
            raise ValueError(f"not one msgpack value: {exc}") from None
        if not isinstance(doc, list) or len(doc) not in (6, 7):
            raise ValueError("expected [kind, component, source, target, plan, state, origin?]")
        kind, component, source, target, key, state = doc[:6]
        origin = doc[6] if len(doc) == 7 else ""
        if not isinstance(origin, str):
            raise ValueError("origin must be a string")
        if kind not in KINDS:
            raise ValueError(f"kind {kind!r} is not one of {', '.join(KINDS)}")
        if not all(isinstance(x, str) and x for x in (component, source, target)):
            raise ValueError("component, source and target must be non-empty strings")
        ok_key = (
            isinstance(key, list)
            and len(key) == 3
            and isinstance(key[0], int)
            and isinstance(key[1], str)
            and isinstance(key[2], int)
        )
        if not ok_key:
            raise ValueError("plan must be [epoch, allocator, version]")
        return cls(kind, component, source, target, (key[0], key[1], key[2]), state, origin)


@dataclass(frozen=True, slots=True)
class Send:
    """Take `source`'s snapshot and hand it to each target (robot, instance)."""

    kind: str
    component: str
    source: str
    targets: tuple[tuple[str, str], ...]


def sync_targets(plan: Plan | None, robot: str) -> dict[str, tuple[str, float, list[Placement]]]:
    """Active instance on `robot` -> (component, sync seconds, its hot standbys), where sync > 0."""
    out: dict[str, tuple[str, float, list[Placement]]] = {}
    if plan is None or plan.system is None:
        return out
    syncs = {c.name: c.standby.sync_s for c in plan.system.components if c.standby.sync_s > 0}
    for p in plan.placements:
        if p.robot != robot or p.role != InstanceRole.ACTIVE or p.component not in syncs:
            continue
        standbys = [
            s
            for s in plan.placements
            if s.component == p.component and s.role == InstanceRole.STANDBY and s.mode == "hot"
        ]
        if standbys:
            out[p.instance] = (p.component, syncs[p.component], standbys)
    return out


@dataclass
class SyncSchedule:
    """When each active instance here last handed its state to its standbys."""

    last: dict[str, float] = field(default_factory=dict)

    def due(self, now: float, plan: Plan | None, robot: str, active: set[str]) -> list[Send]:
        """The syncs to run now; `active` are this robot's instances in ACTIVE."""
        sends: list[Send] = []
        targets = sync_targets(plan, robot)
        for instance, (component, every, standbys) in sorted(targets.items()):
            if instance not in active:
                continue
            if now - self.last.get(instance, float("-inf")) < every:
                continue
            self.last[instance] = now
            pairs = tuple((s.robot, s.instance) for s in standbys)
            sends.append(Send("sync", component, instance, pairs))
        for gone in set(self.last) - set(targets):
            del self.last[gone]
        return sends

    def next_due(self, plan: Plan | None, robot: str) -> float | None:
        """The earliest time a sync falls due (None: nothing syncs here)."""
        targets = sync_targets(plan, robot)
        times = [self.last.get(i, float("-inf")) + every for i, (_, every, _) in targets.items()]
        return min(times) if times else None


def final_target(
    plan: Plan | None, component: str, instance: str, robot: str = ""
) -> tuple[str, str] | None:
    """(robot, instance) that takes a retiring instance's last state: the component's active
    placement, when that is another instance or the same name on another robot than `robot`
    (the retiring one's); None when the component stays or is gone."""
    if plan is None or plan.system is None:
        return None
    active = plan.active_of(component)
    if active is None or (active.instance == instance and active.robot == (robot or active.robot)):
        return None
    return (active.robot, active.instance)


def admit(plan: Plan | None, robot: str, msg: StateMsg) -> str:
    """ "apply", "hold" (ask again later), or why the state is dropped."""
    behind = plan is None or msg.plan > plan.key
    if plan is None or plan.system is None:
        return HOLD if behind and msg.kind == "final" else "no_plan"
    target = next((p for p in plan.placements if p.instance == msg.target), None)
    if target is not None and target.component != msg.component:
        return "wrong_component"
    if target is not None and target.robot != robot:
        return "not_here"
    if msg.kind == "sync":
        if target is None or target.role != InstanceRole.STANDBY:
            return "not_a_standby"
        active = plan.active_of(msg.component)
        if active is None or active.instance != msg.source:
            return "not_from_the_active"
        return APPLY
    if target is not None and target.role == InstanceRole.ACTIVE and msg.source != msg.target:
        return APPLY
    if target is not None and target.role == InstanceRole.ACTIVE and msg.origin not in ("", robot):
        return APPLY  # the same instance name, moved here from the origin robot
    return HOLD if behind else "not_the_active"
