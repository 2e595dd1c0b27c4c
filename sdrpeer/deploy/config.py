"""Deployment timers (the coordinator's), with presets like the other layers' configurations.

Every duration is in seconds. An agent takes these from the preset its `--preset` names
(`sdrpeer.agent.tuning`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any


@dataclass(frozen=True, slots=True)
class DeployConfig:
    """Tunables of the deployment side of an agent. Use a preset (`lan()`, `fast_test()`)."""

    tick: float = 0.2
    """Seconds between steps while a plan is held or this robot is the allocator (their duties
    poll: state handoff, re-allocation retries)."""
    idle_tick: float = 2.0
    """Seconds between steps of an idle fleet (nothing deployed)."""
    adopt_after: float = 1.0
    """Seconds a new allocator waits to hear of a newer plan before it re-issues the newest it
    holds (at once when no robot gossips a newer one)."""
    retry_every: float = 5.0
    """Seconds before the allocator tries again an allocation that was infeasible."""
    handover_wait: float = 10.0
    """Seconds an active placement waits for the component's old copy on another alive robot to
    stand down before it activates anyway. The component runs meanwhile (the old copy is
    ACTIVE); a robot cut off drops out of the view at its death and is not waited for, so this
    bound is only a safety valve (a robot alive in gossip whose plan never arrives: a lossy link
    in a 10-robot soak took more than 2.5 s)."""
    fetch_retry: float = 1.0
    """Seconds before a plan is fetched again from a robot a fetch failed from (a robot
    restarting answers gossip before its API: retrying at once made every agent fetch in a
    tight loop)."""
    ask_retry: float = 0.5
    """Seconds before a robot back from a cut asks the fleet for its plan again after an ask
    failed (`deploy.touch_shell`)."""

    def __post_init__(self) -> None:
        for name in ("tick", "idle_tick", "adopt_after", "retry_every", "handover_wait"):
            if getattr(self, name) <= 0:
                raise ValueError(f"deploy {name} must be > 0 (got {getattr(self, name)})")
        for name in ("fetch_retry", "ask_retry"):
            if getattr(self, name) < 0:
                raise ValueError(f"deploy {name} must be >= 0 (got {getattr(self, name)})")

    def with_(self, **changes: Any) -> DeployConfig:
        """A copy with some fields changed."""
        return replace(self, **changes)


def lan() -> DeployConfig:
    """Robots on one Wi-Fi network (the `lan` gossip preset)."""
    return DeployConfig()


def lab() -> DeployConfig:
    """Many agents on one busy machine: the `lan` timers."""
    return DeployConfig()


def fast_test() -> DeployConfig:
    """Loopback tests and the local lab: so far the `lan` timers."""
    return DeployConfig()
