"""An event loop on virtual time, for tests whose outcome depends on the loop clock.

How it works: `VirtualTimeLoop.time()` returns a counter, not the monotonic clock. Whenever the
loop has nothing ready to run, the counter jumps to the earliest scheduled timer, so
`asyncio.sleep(0.5)` takes no wall time and exactly 0.5 s of loop time, however busy the machine
is. Code under test must read time only through the loop (`loop.time()`, `asyncio.sleep`,
`asyncio.timeout`), as the SDK's execution contexts do. It reaches into CPython's
`BaseEventLoop` (`_ready`, `_scheduled`, `_run_once`), which 3.11 to 3.13 share; no real I/O may
be pending while the clock jumps (these tests do none).
"""

from __future__ import annotations

import asyncio
from collections.abc import Coroutine
from typing import Any, TypeVar

T = TypeVar("T")


class VirtualTimeLoop(asyncio.SelectorEventLoop):
    """A selector loop whose clock only moves when everything is waiting for it."""

    def __init__(self) -> None:
        super().__init__()
        self.now = 0.0

    def time(self) -> float:
        return self.now

    def _run_once(self) -> None:
        ready: Any = getattr(self, "_ready")  # noqa: B009 (CPython internals, see above)
        scheduled: Any = getattr(self, "_scheduled")  # noqa: B009
        due = [h.when() for h in scheduled if not h.cancelled()]
        if not ready and due:
            self.now = max(self.now, min(due))
        super()._run_once()  # type: ignore[misc]


def run_virtual(coro: Coroutine[Any, Any, T]) -> T:
    """Run `coro` to completion on a fresh `VirtualTimeLoop`."""
    loop = VirtualTimeLoop()
    try:
        return loop.run_until_complete(coro)
    finally:
        loop.close()
