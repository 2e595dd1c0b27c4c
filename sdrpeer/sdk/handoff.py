"""State handoff: how a component's working state moves to a new instance (migration, recovery).

How it works — the rules:

1. A component may override `on_snapshot(self) -> Any`, returning its working state as a
   msgpack-able value (maps, lists, numbers, strings, bytes, None), and
   `on_restore(self, state) -> None`, taking over such a state from an earlier instance of the same
   class. Both may be `async def`. Without `on_snapshot` the state is None.
2. Where each is allowed (`HANDOFF_STATES`; elsewhere LifecycleError, no callback runs):

   | operation  | allowed in              | why                                                |
   |------------|-------------------------|----------------------------------------------------|
   | `snapshot` | INACTIVE, ACTIVE, ERROR | after a fault, the state is what a successor needs |
   | `restore`  | INACTIVE, ACTIVE        | in ERROR reset first; CREATED has no state yet     |

   A restore in INACTIVE must survive the following activation: a component that starts afresh in
   `on_activated` keeps a restored state instead (see components/position_estimation.py).
3. Neither is a lifecycle transition: a failing `on_snapshot`/`on_restore` is a refusal
   (CallbackError, the command's reply says why) and the component stays in its state. So
   `on_restore` checks the whole state before it changes anything.
4. A component without `on_restore` refuses any state but None.
5. Both run under the runner's lock: never during `on_execute` or another callback.
"""

from __future__ import annotations

import inspect
from collections.abc import Callable
from typing import Any, Final

from sdrpeer.sdk.component import Component
from sdrpeer.sdk.errors import CallbackError, LifecycleError
from sdrpeer.sdk.lifecycle import LifecycleState

__all__ = ["HANDOFF_STATES", "call_restore", "call_snapshot", "check_handoff"]

S = LifecycleState

HANDOFF_STATES: Final[dict[str, frozenset[LifecycleState]]] = {
    "snapshot": frozenset({S.INACTIVE, S.ACTIVE, S.ERROR}),
    "restore": frozenset({S.INACTIVE, S.ACTIVE}),
}

_HINTS: Final[dict[LifecycleState, str]] = {
    S.CREATED: "initialize it first",
    S.ERROR: "reset it first",
    S.FINALIZED: "it is finalized",
}


def check_handoff(operation: str, state: LifecycleState) -> None:
    """LifecycleError unless `operation` (snapshot or restore) is allowed in `state`."""
    if state not in HANDOFF_STATES[operation]:
        raise LifecycleError(operation, state.value, _HINTS.get(state, ""))


async def call_snapshot(component: Component) -> Any:
    """`component.on_snapshot()`; CallbackError if it raises (the component keeps its state)."""
    return await _refusable(component, "on_snapshot", component.on_snapshot)


async def call_restore(component: Component, state: Any) -> None:
    """`component.on_restore(state)`; CallbackError if it raises or there is none (unless None)."""
    if type(component).on_restore is Component.on_restore:
        if state is not None:
            name = type(component).__name__
            raise CallbackError("on_restore", f"{name} has no on_restore: it takes no state")
        return
    await _refusable(component, "on_restore", component.on_restore, state)


async def _refusable(component: Component, name: str, fn: Callable[..., Any], *args: Any) -> Any:
    try:
        result = fn(*args)
        return (await result) if inspect.isawaitable(result) else result
    except Exception as exc:
        text = f"{type(exc).__name__}: {exc}"
        component.log.warning("%s refused: %s", name, text)
        raise CallbackError(name, text) from exc
