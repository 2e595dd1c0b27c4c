"""One rclpy context and executor per host, spun in a thread of its own beside the host's asyncio
loop.

How it works: a component host runs asyncio (the control channel, the data plane, the SDK's
lifecycle); rclpy runs its callbacks in an executor that blocks while it waits. `Spinner`
initialises rclpy's default context (node classes make their nodes there; one per host process)
with the ROS arguments it is given (parameter overrides), and an executor (`EventsExecutor`,
rclpy's fastest, or the `SingleThreadedExecutor` that `rclpy.spin` uses) spun in a daemon thread.
Everything that touches rclpy objects runs in that
thread: `call(fn)` hands `fn` to the executor as a task (rclpy wakes at once) and returns an
`asyncio` future of its result, so node construction, lifecycle transitions and destruction
never race the callbacks. `stuck_for()` is how long the executor has been in one callback (the
ROS 2 form of a hung `on_execute`; the hosting component turns it into an error): the spin loop
notes the time each `spin_once` returns (it runs one callback, or returns after 0.1 s idle), and
`watch(node)`'s 10 Hz timer on a node notes it too. A flood of messages, which can keep that
timer queued behind thousands of callbacks for seconds, is not a stuck executor.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
import threading
import time
from collections.abc import Callable, Sequence
from typing import Any, TypeVar

import rclpy
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.experimental import EventsExecutor  # type: ignore[attr-defined]

__all__ = ["EXECUTORS", "Spinner"]

T = TypeVar("T")
log = logging.getLogger("sdrpeer.ros2.spin")
EXECUTORS = ("events", "single")
_TICK = 0.1


class Spinner:
    """An rclpy context and its executor, spun in a thread (see the module's doc)."""

    def __init__(self, *, args: Sequence[str] = (), executor: str = "events") -> None:
        if executor not in EXECUTORS:
            raise ValueError(f"executor {executor!r}: expected one of {', '.join(EXECUTORS)}")
        rclpy.init(args=["sdrpeer", *args] if args else None)  # the default context: the node
        self.context = rclpy.get_default_context()  # classes make their nodes in it
        kind = EventsExecutor if executor == "events" else SingleThreadedExecutor
        self.executor = kind(context=self.context)
        self._ticked = time.monotonic()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, name="rclpy-spin", daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        try:
            while not self._stop.is_set() and self.context.ok():
                self.executor.spin_once(timeout_sec=_TICK)
                self._ticked = time.monotonic()  # back from a callback (or idle): not stuck
        except (ExternalShutdownException, rclpy.executors.ShutdownException):
            pass
        except Exception:  # a callback raised: rclpy re-raises it here
            log.exception("rclpy executor stopped")
            raise

    @property
    def alive(self) -> bool:
        """Whether the executor thread still runs."""
        return self._thread.is_alive()

    def call(self, fn: Callable[[], T]) -> asyncio.Future[T]:
        """Run `fn` in the executor's thread; its result (or exception) as an asyncio future."""
        done: concurrent.futures.Future[T] = concurrent.futures.Future()

        def run() -> None:
            if not done.set_running_or_notify_cancel():
                return
            try:
                done.set_result(fn())
            except BaseException as exc:  # handed to the awaiting side
                done.set_exception(exc)

        if not self.alive:
            done.set_exception(RuntimeError("the rclpy executor has stopped"))
        else:
            self.executor.create_task(run)
        return asyncio.wrap_future(done)

    def watch(self, node: Any) -> Any:
        """A 10 Hz timer on `node` that also tells `stuck_for` the executor comes round (the
        timer; destroy it with the node)."""
        self._ticked = time.monotonic()
        return node.create_timer(_TICK, self._tick)

    def _tick(self) -> None:
        self._ticked = time.monotonic()

    def stuck_for(self) -> float:
        """Seconds the executor has been in one callback (0 while it keeps coming back)."""
        late = time.monotonic() - self._ticked - _TICK
        return max(0.0, late)

    def check(self, stuck_after: float) -> None:
        """RuntimeError if the executor stopped (a callback raised) or has sat in one callback
        longer than `stuck_after` seconds: what puts a hosting component in ERROR."""
        if not self.alive:
            raise RuntimeError("the rclpy executor stopped (a callback raised: see the log)")
        stuck = self.stuck_for()
        if stuck > stuck_after:
            raise RuntimeError(f"rclpy's executor has been in one callback for {stuck:.1f} s")

    def close(self, timeout: float = 2.0) -> None:
        """Stop the thread and shut the context down (waits up to `timeout` for the thread)."""
        self._stop.set()
        self._thread.join(timeout)
        try:
            self.executor.shutdown(timeout_sec=0.5)
        finally:
            if self.context.ok():
                rclpy.shutdown(context=self.context)
