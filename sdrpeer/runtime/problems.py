"""What the agent hears about trouble in one instance: reported faults and problems seen.

How it works: a host forwards every fault its component reports as a `fault` report
(docs/protocol.md, `sdrpeer.control.messages.Fault`); `fault_from_report` turns it into a `Fault`
(kind and detail as sent, the detail cut to 500 characters, the host's `ts` and our arrival
time). Independently the supervisor sees two *problems* of its own (`problem_of_state` is the
rule for the first):

| cause             | when                                                                 |
|-------------------|----------------------------------------------------------------------|
| `component_error` | a `state ERROR` report while not already in ERROR, not caused by a   |
|                   | fault (a fault's ERROR says `fault`: its `fault` hook already fired)  |
| `crashed`         | the host process ended while nobody asked it to stop (any exit code, |
|                   | a kill by the supervisor for a protocol error or a missing hello too)|

Hooks are called at once, from the report or the exit that caused them; `call_hook` logs an
exception in one and carries on, so a broken hook never stops the supervisor.
"""

from __future__ import annotations

import logging
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

from sdrpeer.control import messages
from sdrpeer.vocabulary import InstanceState, LifecycleState

__all__ = [
    "COMPONENT_ERROR",
    "CRASHED",
    "Fault",
    "call_hook",
    "fault_from_report",
    "problem_of_state",
]

log = logging.getLogger(__name__)

COMPONENT_ERROR: Final = "component_error"
"""A component callback failed: the instance is in ERROR."""
CRASHED: Final = "crashed"
"""The host process ended unexpectedly."""
DETAIL_MAX: Final = 500
"""Characters of a fault's detail kept."""


@dataclass(frozen=True, slots=True)
class Fault:
    """One fault a component reported."""

    kind: str
    """hardware_failure, abnormal_behaviour, emergency_stop (or what a non-Python host sent)."""
    detail: str
    """The component's words, at most DETAIL_MAX characters."""
    ts: float | None
    """When the host sent it (unix seconds, its clock), None if it did not say."""
    received: float
    """When the agent received it (unix seconds)."""

    def to_json(self) -> dict[str, Any]:
        """As shown in an instance's status."""
        return {"kind": self.kind, "detail": self.detail, "ts": self.ts, "received": self.received}


def fault_from_report(msg: messages.Fault, now: float) -> Fault:
    """The Fault in a `fault` report received at `now`."""
    return Fault(kind=msg.kind, detail=msg.detail[:DETAIL_MAX], ts=msg.ts, received=now)


def problem_of_state(current: InstanceState, msg: messages.State, stopping: bool) -> str | None:
    """The problem a `state` report shows, given the supervisor's current state, or None."""
    if (
        msg.state != LifecycleState.ERROR
        or current == LifecycleState.ERROR
        or stopping
        or msg.fault
    ):
        return None
    return COMPONENT_ERROR


def call_hook(name: str, hook: Callable[..., None], *args: Any) -> None:
    """`hook(*args)`, logging (not raising) what it raises."""
    try:
        hook(*args)
    except Exception:
        log.exception("%s hook failed", name)
