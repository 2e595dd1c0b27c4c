"""One rclpy context and executor per host, spun in a thread of its own beside the host's asyncio
loop.

How it works: a component host runs asyncio (the control channel, the data plane, the SDK's
lifecycle); rclpy runs its callbacks in an executor that blocks while it waits. `Spinner`
initialises rclpy's default context (node classes make their nodes there; one per host process)
with the ROS arguments it is given (parameter overrides), and an executor (`EventsExecutor`,
rclpy's fastest, or the `SingleThreadedExecutor` that `rclpy.spin` uses) spun in a daemon thread.
Everything that touches rclpy objects runs in that thread: `await call(fn)` hands `fn` to the
executor as a task (rclpy wakes at once) and returns its result, bounded in time, so node
construction, lifecycle transitions and destruction never race the callbacks and never wait for
ever behind a stuck one. `stuck_for()` is how long the executor has been in one callback (the ROS 2
form of a hung `on_execute`; the hosting component turns it into an error): the spin loop notes the
time each `spin_once` returns (it runs one callback, or returns after 0.1 s idle), and
`watch(node)`'s 10 Hz timer on a node notes it too. A flood of messages, which can keep that timer
queued behind thousands of callbacks for seconds, is not a stuck executor.
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
CALL_TIMEOUT = 30.0
"""Seconds `call` waits for the executor by default (a node's constructor or `configure` may
load a model)."""
STUCK_SKIP = 0.5
"""An executor this late coming back from a callback is not handed teardown work."""


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

    async def call(
        self,
        fn: Callable[[], T],
        timeout: float = CALL_TIMEOUT,  # noqa: ASYNC109 - the bound is the call's contract
    ) -> T:
        """Run `fn` in the executor's thread and return its result (or raise its exception);
        RuntimeError when the executor has stopped, or has not run it within `timeout` seconds
        (it sits in a callback: the caller must not wait for it for ever)."""
        done: concurrent.futures.Future[T] = concurrent.futures.Future()

        def run() -> None:
            if not done.set_running_or_notify_cancel():
                return
            try:
                done.set_result(fn())
            except BaseException as exc:  # handed to the awaiting side
                done.set_exception(exc)

        if not self.alive:
            raise RuntimeError("the rclpy executor has stopped")
        self.executor.create_task(run)
        try:
            async with asyncio.timeout(timeout):
                return await asyncio.wrap_future(done)
        except TimeoutError:
            done.cancel()  # if it has not started, it never will
            raise RuntimeError(
                f"rclpy's executor did not get to it within {timeout:g} s (stuck in a callback)"
            ) from None

    @property
    def usable(self) -> bool:
        """Whether work handed to the executor will run: it is alive and not sitting in a
        callback (teardown skips rclpy when it is not, rather than wait behind that callback)."""
        return self.alive and self.stuck_for() < STUCK_SKIP

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
