"""What the deployment core (`sdrpeer.deploy.core`) asks its shell to do.

How it works: the core never performs I/O; every call into it may queue effects, which the shell
drains with `DeployCore.effects()` and carries out in order: fetch a plan from a robot's API and
report the answer back (`fetched` / `fetch_failed`), push a plan to a robot (fire and forget),
persist and apply a plan the core now holds, set the instance manager's desired instances, and
write an event to the robot's event log (the
shell stamps it with the wall clock and the robot's name).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from sdrpeer.plan import Plan
from sdrpeer.runtime.spec import InstanceSpec


@dataclass(frozen=True, slots=True)
class Fetch:
    """Fetch the plan `robot` holds from its API and report it back (one fetch at a time)."""

    robot: str
    api: str
    """The robot's API address (from its record)."""


@dataclass(frozen=True, slots=True)
class Push:
    """Offer `plan` to `robot` (it fetches the plan itself if the push is lost)."""

    robot: str
    api: str
    plan: Plan


@dataclass(frozen=True, slots=True)
class Adopted:
    """The core now holds `plan`: store it, apply it to the instance manager, publish the record."""

    plan: Plan
    source: str
    """The robot the plan came from (this robot for one it issued)."""


@dataclass(frozen=True, slots=True)
class Desired:
    """This robot's share of the plan: the instance manager's desired specs for the names the
    plan owns (only those that changed need setting), and the names it no longer owns."""

    specs: tuple[InstanceSpec, ...]
    removed: tuple[str, ...] = ()


@dataclass(frozen=True, slots=True)
class Log:
    """An entry for the robot's event log."""

    kind: str
    detail: dict[str, Any] = field(default_factory=dict)


Effect = Fetch | Push | Adopted | Desired | Log
"""Everything the core may ask for."""
