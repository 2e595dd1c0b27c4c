"""The RT-Component lifecycle as a transition table (OpenRTM-aist, ROS 2 managed nodes).

How it works — the rules:

1. Everything that decides whether a lifecycle change is legal lives in `TRANSITIONS`:
   `TRANSITIONS[state][event] -> next state`. A pair missing from the table is illegal and
   `next_state` raises `LifecycleError` with a hint saying what to do instead.
2. The table is pure data: no callbacks, no I/O, no clock. `ComponentRunner` (sdrpeer.sdk.runner)
   runs the callbacks around each transition:
   initialize -> on_initialize, activate -> on_activated, deactivate -> on_deactivated,
   error -> on_aborting (only when leaving ACTIVE), reset -> on_reset, finalize -> on_finalize.
3. A callback that fails sends the component to ERROR with the `error` event: from ACTIVE (via
   on_aborting), from INACTIVE (on_activated or a params callback failed) and from CREATED
   (on_initialize failed; docs/protocol.md then reports `state ERROR`).
4. ERROR is left only by `reset` (to INACTIVE) or `finalize`. FINALIZED is terminal.
5. `finalize` is not allowed from ACTIVE: deactivate first (the runner does it for you).
"""

from __future__ import annotations

from typing import Final

from sdrpeer.sdk.errors import LifecycleError
from sdrpeer.vocabulary import LifecycleState

__all__ = ["EVENTS", "TRANSITIONS", "LifecycleError", "LifecycleState", "next_state"]


S = LifecycleState

EVENTS: Final = ("initialize", "activate", "deactivate", "error", "reset", "finalize")

TRANSITIONS: Final[dict[LifecycleState, dict[str, LifecycleState]]] = {
    S.CREATED: {"initialize": S.INACTIVE, "error": S.ERROR, "finalize": S.FINALIZED},
    S.INACTIVE: {"activate": S.ACTIVE, "error": S.ERROR, "finalize": S.FINALIZED},
    S.ACTIVE: {"deactivate": S.INACTIVE, "error": S.ERROR},
    S.ERROR: {"reset": S.INACTIVE, "finalize": S.FINALIZED},
    S.FINALIZED: {},
}

# Why an event is refused in a state, for the message (only where there is something to say).
_HINTS: Final[dict[tuple[LifecycleState, str], str]] = {
    (S.CREATED, "activate"): "initialize it first",
    (S.CREATED, "deactivate"): "it was never activated",
    (S.CREATED, "reset"): "it is not in ERROR",
    (S.INACTIVE, "initialize"): "already initialized",
    (S.INACTIVE, "deactivate"): "it is not active",
    (S.INACTIVE, "reset"): "it is not in ERROR",
    (S.ACTIVE, "initialize"): "already initialized",
    (S.ACTIVE, "activate"): "already active",
    (S.ACTIVE, "reset"): "it is not in ERROR",
    (S.ACTIVE, "finalize"): "deactivate it first",
    (S.ERROR, "initialize"): "reset it first",
    (S.ERROR, "activate"): "reset it first",
    (S.ERROR, "deactivate"): "reset it first",
    (S.ERROR, "error"): "already in ERROR",
}


def next_state(state: LifecycleState, event: str) -> LifecycleState:
    """The state after `event` in `state`; raises LifecycleError if the table has no such move."""
    if event not in EVENTS:
        raise ValueError(f"unknown lifecycle event {event!r} (known: {', '.join(EVENTS)})")
    try:
        return TRANSITIONS[state][event]
    except KeyError:
        hint = _HINTS.get((state, event), "it is finalized" if state is S.FINALIZED else "")
        raise LifecycleError(event, state.value, hint) from None
