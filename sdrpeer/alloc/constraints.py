"""The paper's Tables I and II as constraint plugins, and the registry that finds them.

How it works: there are two kinds of constraint.
- A `RobotConstraint` (Table I) answers "does this robot, with what this plan already put on it,
  accept one more instance that needs `need`?". `RobotLoad` is the robot plus what the plan adds
  to it beyond what runs there now; `need` is what the new instance adds (nothing for an instance
  that already runs there). A `static` constraint depends only on the robot and is checked once
  per robot; `cold = False` means a cold standby (placed, not running) is exempt.
- A `LinkConstraint` (Table II) answers "may two robots carry a connection between them?"; it is
  checked once per pair of robots for every connection whose two ends land on different robots,
  with the link measured between them (the worse direction) and their distance.
Each `check` returns None when the constraint holds and otherwise a short reason for a person.
A constraint whose threshold is None is not `enabled` and is never called, with one exception:
memory is a capacity, so without a threshold an instance must still fit in the free memory
(nothing may be left, but not less than nothing); CPU has no such floor (too much CPU only slows
everything down, too much memory gets processes killed).

Unknown metrics: a robot that reports no battery (mains power), no RSSI (wired) or no position
passes the battery, RSSI and distance constraints; they describe hardware it does not have. A
jitter, loss or delay threshold with no link measured between the two robots fails
("no link measurement"): a link nobody measured cannot be vouched for.

Built-ins are entry points of the `sdrpeer.constraints` group (pyproject.toml) and always apply;
`AllocationDef.constraints` names extra plugins from the same group, or any registered in-process
with `CONSTRAINTS.register(name, obj)`.
"""

from __future__ import annotations

from dataclasses import dataclass

from sdrpeer.alloc.view import RobotView
from sdrpeer.plugins.registry import Registry
from sdrpeer.record.robot import LinkStats
from sdrpeer.system.model import ComponentDef, Thresholds
from sdrpeer.units import format_size


@dataclass(slots=True)
class RobotLoad:
    """A robot and what the plan being built adds to it beyond what runs there now."""

    robot: RobotView
    cpu_pct: float = 0.0
    """CPU of the instances placed here that are not running here yet."""
    mem_bytes: int = 0
    """Memory of the instances placed here that are not running here yet."""


@dataclass(frozen=True, slots=True)
class Need:
    """What one more instance adds to a robot (less what an instance already running there uses)."""

    cpu_pct: float = 0.0
    mem_bytes: int = 0


class RobotConstraint:
    """Table I: a condition one robot must meet to take one more instance."""

    name = ""
    """The entry point name (used in reasons)."""
    static = False
    """True when the answer depends only on the robot (checked once per robot per allocation)."""
    cold = True
    """False when cold standbys are exempt (they are placed but use no CPU or memory)."""

    def enabled(self, t: Thresholds) -> bool:
        """Whether this constraint is checked at all under these thresholds."""
        return True

    def check(
        self, load: RobotLoad, need: Need, component: ComponentDef, t: Thresholds
    ) -> str | None:
        """None when the robot accepts the instance, else why not."""
        raise NotImplementedError


class LinkConstraint:
    """Table II: a condition two robots must meet to carry a connection between them."""

    name = ""
    """The entry point name (used in reasons)."""

    def enabled(self, t: Thresholds) -> bool:
        """Whether this constraint is checked at all under these thresholds."""
        return True

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        """None when robots `a` and `b` may be connected, else why not."""
        raise NotImplementedError


def _pct(x: float) -> str:
    return f"{x:.4g}%"


class CpuBelow(RobotConstraint):
    """CPU after adding the instance below `cpu_below_pct` (robot CPU + plan's + need)."""

    name = "cpu"
    cold = False

    def enabled(self, t: Thresholds) -> bool:
        return t.cpu_below_pct is not None

    def check(
        self, load: RobotLoad, need: Need, component: ComponentDef, t: Thresholds
    ) -> str | None:
        limit = t.cpu_below_pct
        after = load.robot.metrics.cpu_pct + load.cpu_pct + need.cpu_pct
        if limit is None or after < limit:
            return None
        added = _pct(need.cpu_pct)
        return f"cpu {_pct(after)} after adding {added} would not be below {_pct(limit)}"


class MemFreeAbove(RobotConstraint):
    """Free memory after adding the instance above `mem_free_above_bytes` (without one: >= 0)."""

    name = "memory"
    cold = False

    def check(
        self, load: RobotLoad, need: Need, component: ComponentDef, t: Thresholds
    ) -> str | None:
        limit = t.mem_free_above_bytes
        free = load.robot.metrics.mem_free - load.mem_bytes
        after = free - need.mem_bytes
        if limit is None:
            if after >= 0:
                return None
            return f"needs {format_size(need.mem_bytes)}, only {format_size(free)} free"
        if after > limit:
            return None
        return (
            f"free memory {format_size(after)} after adding {format_size(need.mem_bytes)} "
            f"would not be above {format_size(limit)}"
        )


class BatteryAbove(RobotConstraint):
    """Battery above `battery_above_pct`; a robot without a battery passes."""

    name = "battery"
    static = True

    def enabled(self, t: Thresholds) -> bool:
        return t.battery_above_pct is not None

    def check(
        self, load: RobotLoad, need: Need, component: ComponentDef, t: Thresholds
    ) -> str | None:
        limit = t.battery_above_pct
        level = load.robot.metrics.battery_pct
        if limit is None or level is None or level > limit:
            return None
        return f"battery {_pct(level)} not above {_pct(limit)}"


class RssiAbove(LinkConstraint):
    """Both robots' RSSI above `rssi_above_dbm`; a robot without a radio (None) passes."""

    name = "rssi"

    def enabled(self, t: Thresholds) -> bool:
        return t.rssi_above_dbm is not None

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        limit = t.rssi_above_dbm
        if limit is None:
            return None
        for r in (a, b):
            rssi = r.metrics.rssi_dbm
            if rssi is not None and rssi <= limit:
                return f"rssi of {r.name} {rssi:.4g}dBm not above {limit:.4g}dBm"
        return None


class JitterBelow(LinkConstraint):
    """Measured jitter between the two robots below `jitter_below_ms`."""

    name = "jitter"

    def enabled(self, t: Thresholds) -> bool:
        return t.jitter_below_ms is not None

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        limit = t.jitter_below_ms
        if limit is None:
            return None
        if link is None:
            return "no link measurement"
        if link.jitter_ms < limit:
            return None
        return f"jitter {link.jitter_ms:.4g}ms not below {limit:.4g}ms"


class DistanceBelow(LinkConstraint):
    """The two robots closer than `distance_below_m`; an unknown position passes."""

    name = "distance"

    def enabled(self, t: Thresholds) -> bool:
        return t.distance_below_m is not None

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        limit = t.distance_below_m
        if limit is None or distance is None or distance < limit:
            return None
        return f"distance {distance:.4g}m not below {limit:.4g}m"


class LossBelow(LinkConstraint):
    """Measured packet loss between the two robots below `loss_below` (a fraction)."""

    name = "loss"

    def enabled(self, t: Thresholds) -> bool:
        return t.loss_below is not None

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        limit = t.loss_below
        if limit is None:
            return None
        if link is None:
            return "no link measurement"
        if link.loss < limit:
            return None
        return f"loss {link.loss:.1%} not below {limit:.1%}"


class DelayBelow(LinkConstraint):
    """Measured round-trip time between the two robots below `delay_below_ms`."""

    name = "delay"

    def enabled(self, t: Thresholds) -> bool:
        return t.delay_below_ms is not None

    def check(
        self,
        a: RobotView,
        b: RobotView,
        link: LinkStats | None,
        distance: float | None,
        t: Thresholds,
    ) -> str | None:
        limit = t.delay_below_ms
        if limit is None:
            return None
        if link is None:
            return "no link measurement"
        if link.rtt_ms < limit:
            return None
        return f"delay {link.rtt_ms:.4g}ms not below {limit:.4g}ms"


CONSTRAINTS: Registry[RobotConstraint | LinkConstraint] = Registry(
    "sdrpeer.constraints",
    (RobotConstraint, LinkConstraint),
    "allocation constraint",
)
"""Every constraint plugin by name (entry points of `sdrpeer.constraints`, plus registered)."""

BUILTIN = ("cpu", "memory", "battery", "rssi", "jitter", "distance", "loss", "delay")
"""The constraints of Tables I and II (and loss, delay), applied to every allocation."""


def active_constraints(
    extra: tuple[str, ...], t: Thresholds
) -> tuple[list[RobotConstraint], list[LinkConstraint]]:
    """The enabled robot and link constraints: the built-ins, then `extra` plugins by name."""
    robot: list[RobotConstraint] = []
    link: list[LinkConstraint] = []
    for name in dict.fromkeys(BUILTIN + extra):
        c = CONSTRAINTS.get(name)
        if not c.enabled(t):
            continue
        if isinstance(c, RobotConstraint):
            robot.append(c)
        else:
            link.append(c)
    return robot, link
