"""`sdrpeer run FILE --robot NAME`: a whole system on one robot, without the allocator.

How it works: the system file is loaded and checked like `sdrpeer deploy` does (every problem
with file:line), then every component's active instance is placed on the named robot (standbys,
requirements and allocation thresholds are ignored: this is for development on one machine) and
the plan's instance specs are what that robot's agent is asked to run.
"""

from __future__ import annotations

from pathlib import Path

from sdrpeer.deploy.derive import specs_for_robot
from sdrpeer.plan import Placement, Plan
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.system.loader import load_system
from sdrpeer.system.model import SystemDef


def specs_on_one_robot(system: SystemDef, robot: str) -> list[InstanceSpec]:
    """Every component of `system` as one active instance on `robot`, wired as the file says."""
    placements = tuple(Placement(c.name, c.name, robot) for c in system.components)
    return specs_for_robot(Plan(0, 0, system, placements, robot), robot, {})


def load_on_one_robot(path: Path | str, robot: str) -> list[InstanceSpec]:
    """Load a system file and give its instance specs for one robot (ConfigError if invalid)."""
    return specs_on_one_robot(load_system(path), robot)
