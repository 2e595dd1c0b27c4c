"""Readings: every Table I/II constraint of the running placements, measured now (pure).

How it works: `readings(system, placements, view)` takes the plan's active placements and the
allocator's current view of the robots (their gossiped records and vitals) and returns one
`Reading` per constraint that applies:
- Table I, per active instance, on its robot: `cpu` (the robot's CPU, must stay below),
  `memory` (its free memory, above), `battery` (above), each under the fleet's thresholds
  narrowed by the component's own (`Thresholds.stricter`);
- Table II, per connection whose two actives run on different robots, under the fleet's bounds
  narrowed by the connection's own: `rssi` (the lower of the two robots' RSSI, above),
  `jitter`, `loss`, `delay` (the link between the two robots as `RobotView.link_to` gives it:
  the worse of what the two ends measure with their gossip probes; delay is the smoothed round
  trip, not half of it), `distance` (below).
A reading's value is None when nothing is measured (no battery, no radio, no position, no probe
answered yet): it is neither kept nor violated. Unlike placement, which asks whether a robot
would still pass *after* adding an instance, a reading compares what the robot reports now (its
figures already count what runs there). Constraint plugins (`allocation.plugins`) are checked
at placement only: they answer yes or no and give no value to watch.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass

from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.plan import Placement
from sdrpeer.system.model import ConnectionDef, SystemDef, Thresholds
from sdrpeer.vocabulary import InstanceRole

ROBOT_CONSTRAINTS = (
    ("cpu", "cpu_below_pct", False),
    ("memory", "mem_free_above_bytes", True),
    ("battery", "battery_above_pct", True),
)
"""Table I: (constraint, Thresholds field, True when the value must stay above the bound)."""
LINK_CONSTRAINTS = (
    ("rssi", "rssi_above_dbm", True),
    ("jitter", "jitter_below_ms", False),
    ("loss", "loss_below", False),
    ("delay", "delay_below_ms", False),
    ("distance", "distance_below_m", False),
)
"""Table II, the same way."""
UNITS = {
    "cpu": "%",
    "memory": "B",
    "battery": "%",
    "rssi": "dBm",
    "jitter": "ms",
    "loss": "",
    "delay": "ms",
    "distance": "m",
}
"""The unit of each constraint's value and bound (loss is a fraction 0..1)."""


@dataclass(frozen=True, slots=True)
class Reading:
    """One constraint of one running placement, measured now."""

    component: str
    """The component whose placement this is about (for a connection: its receiver)."""
    constraint: str
    """cpu, memory, battery (Table I); rssi, jitter, loss, delay, distance (Table II)."""
    subject: str
    """The robot (Table I) or the connection id (Table II, `Cam.image->Det.image`)."""
    robots: tuple[str, ...]
    """The robot (Table I), or the sender's and the receiver's robots (Table II)."""
    value: float | None
    """What is measured now, in the unit of `UNITS` (None: nothing measured)."""
    bound: float
    above: bool
    """True: the value must stay above the bound; False: below."""
    movable: tuple[str, ...] = ()
    """The components a move could fix it with, in the order to try (receiver first)."""

    @property
    def key(self) -> tuple[str, str, tuple[str, ...]]:
        """What one tracker follows: the constraint, its subject and the robots involved (a
        placement that moved is a new key)."""
        return (self.constraint, self.subject, self.robots)

    def violated(self) -> bool | None:
        """Whether the value is at or past the bound now (None: not measured)."""
        if self.value is None:
            return None
        return self.value <= self.bound if self.above else self.value >= self.bound


def readings(
    system: SystemDef, placements: Iterable[Placement], view: ClusterView
) -> list[Reading]:
    """Every constraint that applies to the active placements in `placements` on robots in
    `view` (see the module docstring), Table I first, in the system's order."""
    fleet = system.allocation.thresholds
    where: dict[str, RobotView] = {}
    for p in placements:
        robot = view.robot(p.robot)
        if p.role == InstanceRole.ACTIVE and robot is not None:
            where[p.component] = robot
    out: list[Reading] = []
    for comp in system.components:
        robot = where.get(comp.name)
        if robot is None:
            continue
        t = fleet.stricter(comp.thresholds)
        m = robot.metrics
        values = {"cpu": m.cpu_pct, "memory": float(m.mem_free), "battery": m.battery_pct}
        for name, attr, above in ROBOT_CONSTRAINTS:
            bound = getattr(t, attr)
            if bound is not None:
                out.append(
                    Reading(
                        comp.name,
                        name,
                        robot.name,
                        (robot.name,),
                        values[name],
                        float(bound),
                        above,
                        () if comp.pin is not None else (comp.name,),
                    )
                )
    pins = {c.name: c.pin for c in system.components}
    for c in system.connections:
        a, b = where.get(c.from_component), where.get(c.to_component)
        if a is None or b is None or a.name == b.name:
            continue
        out.extend(_link_readings(c, fleet.stricter(c.bounds), a, b, pins))
    return out


def _link_readings(
    c: ConnectionDef, t: Thresholds, a: RobotView, b: RobotView, pins: dict[str, str | None]
) -> list[Reading]:
    """The Table II readings of connection `c` between robots `a` (sender) and `b`."""
    sender, receiver = c.from_component, c.to_component
    movable = tuple(c for c in (receiver, sender) if pins.get(c) is None)
    link = a.link_to(b)
    rssi = [r for r in (a.metrics.rssi_dbm, b.metrics.rssi_dbm) if r is not None]
    values = {
        "rssi": min(rssi) if rssi else None,
        "jitter": None if link is None else link.jitter_ms,
        "loss": None if link is None else link.loss,
        "delay": None if link is None else link.rtt_ms,
        "distance": a.distance_to(b),
    }
    out = []
    for name, attr, above in LINK_CONSTRAINTS:
        bound = getattr(t, attr)
        if bound is not None:
            out.append(
                Reading(
                    receiver,
                    name,
                    c.id,
                    (a.name, b.name),
                    values[name],
                    float(bound),
                    above,
                    movable,
                )
            )
    return out
