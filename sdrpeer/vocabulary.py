"""The words the platform's parts share: instance states, instance roles, member states.

How it works — the rules (h11's `_state.py`: every word defined once, here):

1. Each word is one member of one enum below, spelled the way the program and the HTTP API
   spell it (`LifecycleState.ACTIVE` is "ACTIVE" in GET /v1/instances; `InstanceRole.STANDBY`
   is "standby" in plans and specs; `MemberState.SUSPECT` is "suspect" in GET /v1/members).
   They are `StrEnum`s, so a member is equal to that spelling and JSON shows it unchanged.
2. An instance's state is one of two concepts: the component's own lifecycle (`LifecycleState`,
   what its host reports in `state` messages and the SDK's transition table moves between), or
   the state of its host process around it as the agent's supervisor sees it (`ProcessState`).
   `InstanceState` is either.
3. Compact wire spellings (lower case in gossip records and their JSON, small integers on the
   wire) are a codec's business, never a consumer's: `sdrpeer.record.robot` (instance states and
   roles in records), `sdrpeer.gossip.wire` (member states in packets), `sdrpeer.runtime.spec` (a
   spec's `desired`), `sdrpeer.runtime.control` (the host's `state` reports). This module
   imports nothing from sdrpeer.
"""

from __future__ import annotations

from enum import StrEnum

__all__ = [
    "InstanceRole",
    "InstanceState",
    "LifecycleState",
    "MemberState",
    "ProcessState",
]


class LifecycleState(StrEnum):
    """A component's lifecycle state; values are the names reported in `state` messages."""

    CREATED = "CREATED"
    INACTIVE = "INACTIVE"
    ACTIVE = "ACTIVE"
    ERROR = "ERROR"
    FINALIZED = "FINALIZED"


class ProcessState(StrEnum):
    """The state of an instance's host process, where the component's own state is not known."""

    STOPPED = "STOPPED"
    """No host runs (never started, stopped, or between lives)."""
    STARTING = "STARTING"
    """Spawned (or being spawned), not initialized yet."""
    STOPPING = "STOPPING"
    """Being stopped: exit, then SIGTERM, then SIGKILL."""
    BACKOFF = "BACKOFF"
    """Exited unasked; waiting the restart delay."""
    FAILED = "FAILED"
    """Exited too often too fast: not restarted until started again."""
    UPDATING = "UPDATING"
    """A robot's record only: the running host has a spec older than the desired one."""


InstanceState = LifecycleState | ProcessState
"""What an instance's state is: its component's lifecycle while its host runs one, else its
process's."""


class InstanceRole(StrEnum):
    """What an instance is in its component's placement."""

    ACTIVE = "active"
    """The instance that does the work (kept ACTIVE when desired so)."""
    STANDBY = "standby"
    """A spare, kept INACTIVE (warm) or not started (cold)."""


class MemberState(StrEnum):
    """What the membership protocol believes of a robot."""

    ALIVE = "alive"
    SUSPECT = "suspect"
    """Its probes failed; it is declared dead unless it refutes in time."""
    DEAD = "dead"
    LEFT = "left"
    """It left gracefully."""
