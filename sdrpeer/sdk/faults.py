"""Faults a component detects itself (Table III of the paper) and what each does to the lifecycle.

How it works — the rules:

1. A component calls `report_fault(kind, detail)`, or one of `hardware_failure(detail)`,
   `abnormal_behaviour(detail)`, `emergency_stop(detail)`, from any callback (sync or async) or
   from a thread it started. The kind is checked in the caller (ValueError if unknown).
2. `FAULT_EFFECTS` decides, per kind, whether the fault also moves the component to ERROR:

   | kind                 | effect  | why                                                        |
   |----------------------|---------|------------------------------------------------------------|
   | `hardware_failure`   | ERROR   | a device is gone: `on_execute` cannot do its work          |
   | `emergency_stop`     | ERROR   | the robot must stop now: `on_aborting` makes it safe       |
   | `abnormal_behaviour` | report  | the component still works; the agent decides what to do    |

3. `FaultRelay.report` is what `Component.report_fault` calls. It hands a report made on another
   thread to the loop's thread (`call_soon_threadsafe`); on the loop's thread it calls the fault
   hooks at once (the host sends the `fault` report from there), then, for an ERROR kind,
   remembers the move as *pending* and starts a task that has the runner apply it.
4. The runner applies a pending move under its lock, before any other callback, transition or
   execution, so callbacks still never interleave: ACTIVE -> ERROR runs `on_aborting`, INACTIVE
   or CREATED -> ERROR does not; in ERROR or FINALIZED it is dropped. The reported state carries
   the fault's kind, so the agent can tell it from a failing callback.
5. Only the first pending fault counts until the runner has applied it.
"""

from __future__ import annotations

import asyncio
import logging
from collections.abc import Callable, Coroutine
from enum import StrEnum
from typing import Any, Final

__all__ = [
    "FAULT_EFFECTS",
    "FAULT_KINDS",
    "FaultEffect",
    "FaultHook",
    "FaultRelay",
    "check_kind",
    "fault_text",
    "moves_to_error",
]

log = logging.getLogger("sdrpeer.sdk.faults")

FaultHook = Callable[[str, str], None]
"""`hook(kind, detail)`, called on the loop's thread."""


class FaultEffect(StrEnum):
    """What a fault does besides being reported."""

    REPORT = "report"
    """Only reported: the component stays in its state."""
    ERROR = "error"
    """Reported, then the component moves to ERROR (through `on_aborting` when ACTIVE)."""


FAULT_EFFECTS: Final[dict[str, FaultEffect]] = {
    "hardware_failure": FaultEffect.ERROR,
    "abnormal_behaviour": FaultEffect.REPORT,
    "emergency_stop": FaultEffect.ERROR,
}
FAULT_KINDS: Final = tuple(FAULT_EFFECTS)


def check_kind(kind: str) -> None:
    """ValueError unless `kind` is one of FAULT_KINDS."""
    if kind not in FAULT_EFFECTS:
        raise ValueError(f"report_fault: kind {kind!r} not in {', '.join(FAULT_KINDS)}")


def moves_to_error(kind: str) -> bool:
    """Whether a fault of `kind` moves the component to ERROR (see the table above)."""
    return FAULT_EFFECTS.get(kind) is FaultEffect.ERROR


def fault_text(kind: str, detail: str) -> str:
    """The error text of a fault's ERROR state: `emergency_stop: bumper pressed`."""
    return f"{kind}: {detail}" if detail else kind


def _running_loop() -> asyncio.AbstractEventLoop | None:
    try:
        return asyncio.get_running_loop()
    except RuntimeError:
        return None


class FaultRelay:
    """Carries fault reports to the loop's thread, calls the hooks, keeps one pending ERROR move."""

    def __init__(self, apply: Callable[[], Coroutine[Any, Any, None]]) -> None:
        self.hooks: list[FaultHook] = []
        """Called with `(kind, detail)` for every fault, in order."""
        self.loop: asyncio.AbstractEventLoop | None = _running_loop()
        """The loop the runner lives on (set again when the runner initializes)."""
        self.pending: tuple[str, str] | None = None
        """`(kind, error text)` of a move to ERROR not yet applied by the runner."""
        self._apply = apply
        self._task: asyncio.Task[None] | None = None

    def report(self, kind: str, detail: str) -> None:
        """Report a fault from any thread (Component.report_fault calls this)."""
        loop = self.loop
        if loop is not None and _running_loop() is not loop:
            try:
                loop.call_soon_threadsafe(self._deliver, kind, detail)
            except RuntimeError:  # the loop is closed: the host is exiting
                log.warning("fault %s after the loop closed: not reported", kind)
            return
        self._deliver(kind, detail)

    def take(self) -> tuple[str, str] | None:
        """The pending move to ERROR, now cleared (None if there is none)."""
        due, self.pending = self.pending, None
        return due

    def _deliver(self, kind: str, detail: str) -> None:
        for hook in tuple(self.hooks):
            try:
                hook(kind, detail)
            except Exception:
                log.exception("on_fault hook failed")
        if moves_to_error(kind) and self.pending is None:
            self.pending = (kind, fault_text(kind, detail))
            loop = _running_loop()  # None only before the runner's loop runs: its start settles it
            if loop is not None and (self._task is None or self._task.done()):
                self._task = loop.create_task(self._apply())  # applies it under the runner's lock
