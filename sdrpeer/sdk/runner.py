"""`ComponentRunner`: drives one Component instance through its lifecycle on an asyncio loop.

How it works: every transition looks up the next state in sdrpeer.sdk.lifecycle's table first
(an illegal one raises LifecycleError before any callback runs), then runs the callback, then
changes state. One `asyncio.Lock` serialises transitions, params changes and executions, so an
`async def` callback is never interleaved with another one. A callback that raises makes
`_fail` record `last_error`, switch to ERROR and call the `on_state` hooks synchronously, in the
same loop iteration as the exception, and only then run `on_aborting` (when leaving ACTIVE); the
transition method then raises CallbackError (the host answers `reply ok=false` with its text).
One background task is the execution context: `Periodic` keeps a grid of deadlines (skipping
ahead when it falls a whole period behind) and sleeps on a future that state and params changes
wake early; `OnInput` runs once per frame accepted by the port and not yet consumed; `Stepped`
has no task: `step(n)` runs n executions when the caller says. While ACTIVE it calls
`on_execute`; while in ERROR `on_error` (a failure there is logged once). `on_startup` follows
`on_initialize` (the context starts), `on_shutdown` precedes `on_finalize`, and a
`Periodic(param=...)` rate changed while running calls `on_rate_changed(hz)`.
Because a transition waits for a running `on_execute`, an async `on_execute` must return
(read with `read()`/`get_nowait()`, not an endless `async for`). Faults (sdrpeer.sdk.faults) reach
the `on_fault` hooks at once; a move to ERROR they ask for is applied by `_settle`, the first
thing everything does under the lock. `snapshot`/`restore` (sdrpeer.sdk.handoff) run
`on_snapshot`/`on_restore` under the lock too; their failures are refusals, not ERROR.
"""

from __future__ import annotations

import asyncio
import contextlib
import functools
import inspect
from collections.abc import Callable, Mapping
from typing import Any, Final

from sdrpeer.sdk.component import Component
from sdrpeer.sdk.errors import CallbackError, LifecycleError
from sdrpeer.sdk.execution import OnInput, Periodic, Stepped
from sdrpeer.sdk.faults import FaultHook, FaultRelay
from sdrpeer.sdk.handoff import call_restore, call_snapshot, check_handoff
from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.lifecycle import LifecycleState, next_state

__all__ = ["ComponentRunner", "StateHook"]

S = LifecycleState
StateHook = Callable[[LifecycleState, str | None], None]
_RUNNING: Final = frozenset({S.ACTIVE, S.ERROR})
_EARLY: Final = 1e-6  # a timer that fires this close to its deadline counts as on time


def _wake(fut: asyncio.Future[None]) -> None:
    if not fut.done():
        fut.set_result(None)


class ComponentRunner:
    """Owns one component instance: lifecycle commands, params, execution context, hooks."""

    def __init__(self, component: Component) -> None:
        self.component = component
        self.executions = 0
        """How many times `on_execute` was called."""
        self._state = S.CREATED
        self._state_hooks: list[StateHook] = []
        self.fault: str | None = None
        """The fault kind that put the component in ERROR (None: a callback failed, or no ERROR)."""
        self._faults = FaultRelay(self._apply_fault)
        self._lock = asyncio.Lock()
        self._task: asyncio.Task[None] | None = None
        self._waiter: asyncio.Future[None] | None = None
        self._pending = 0
        self._initialized = False
        self._started = False  # on_startup succeeded: on_shutdown is owed at finalize
        self._on_error_failed = False
        component._fault_hook = self._faults.report
        ex = type(component).execution
        self._input: InPortRuntime | None = None
        if isinstance(ex, OnInput):
            self._input = component.inport(ex.port)
            self._input._listener = self._on_input

    # -- observing -------------------------------------------------------------------------

    @property
    def state(self) -> LifecycleState:
        """The current lifecycle state."""
        return self._state

    @property
    def last_error(self) -> str | None:
        """The text of the last callback failure ("on_execute: ValueError: ..."), or None."""
        return self.component.last_error

    def on_state(self, callback: StateHook) -> None:
        """Call `callback(state, error)` synchronously on every change (error: why, or None)."""
        self._state_hooks.append(callback)

    def on_fault(self, callback: FaultHook) -> None:
        """Call `callback(kind, detail)` on the loop, at once, for every fault reported."""
        self._faults.hooks.append(callback)

    # -- lifecycle commands ----------------------------------------------------------------

    async def initialize(self) -> None:
        """CREATED -> INACTIVE (on_initialize); starts the execution context."""
        self._faults.loop = asyncio.get_running_loop()
        async with self._lock:
            await self._settle()
            target = next_state(self._state, "initialize")
            self._start()
            await self._guarded("on_initialize", self.component.on_initialize)
            self._initialized = True
            await self._guarded("on_startup", self.component.on_startup)
            self._started = True
            self._set(target)

    async def activate(self) -> None:
        """INACTIVE -> ACTIVE (on_activated)."""
        async with self._lock:
            await self._settle()
            target = next_state(self._state, "activate")
            await self._guarded("on_activated", self.component.on_activated)
            self._set(target)

    async def deactivate(self) -> None:
        """ACTIVE -> INACTIVE (on_deactivated); waits for a running on_execute to finish."""
        async with self._lock:
            await self._settle()
            target = next_state(self._state, "deactivate")
            await self._guarded("on_deactivated", self.component.on_deactivated)
            self._set(target)

    async def reset(self) -> None:
        """ERROR -> INACTIVE (on_reset; then on_initialize and on_startup if they had never
        succeeded)."""
        async with self._lock:
            await self._settle()
            target = next_state(self._state, "reset")
            await self._guarded("on_reset", self.component.on_reset)
            if not self._initialized:
                await self._guarded("on_initialize", self.component.on_initialize)
                self._initialized = True
            if not self._started:
                await self._guarded("on_startup", self.component.on_startup)
                self._started = True
            self._on_error_failed = False
            self._set(target)

    async def finalize(self) -> None:
        """-> FINALIZED (on_deactivated first if ACTIVE, then on_finalize); stops execution.

        A failing on_finalize is logged and reported with the FINALIZED state, not raised.
        """
        async with self._lock:
            await self._settle()
            if self._state is S.ACTIVE:
                with contextlib.suppress(CallbackError):  # now in ERROR: finalize from there
                    await self._guarded("on_deactivated", self.component.on_deactivated)
                    self._set(S.INACTIVE)
            target = next_state(self._state, "finalize")
            error: str | None = None
            names = ("on_shutdown", "on_finalize") if self._started else ("on_finalize",)
            for name in names:
                try:
                    await self._call(getattr(self.component, name))
                except Exception as exc:
                    error = self._record(name, exc)
            self._set(target, error)
            task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task

    async def set_params(self, params: Mapping[str, Any]) -> dict[str, Any]:
        """Check and apply params (all or none; ParamError), run their callbacks; -> changed ones.

        Before initialize (CREATED) values are applied without callbacks.
        """
        values = self.component.convert_params(params)
        async with self._lock:
            await self._settle()
            if self._state is S.FINALIZED:
                raise LifecycleError("set_params", S.FINALIZED.value, "it is finalized")
            current = self.component._param_values
            changed = {k: v for k, v in values.items() if not _same(current[k], v)}
            current.update(changed)
            self._kick()  # a Periodic(param=...) rate may have changed
            if not changed or self._state is S.CREATED:
                return changed
            declared = type(self.component)._sdk_params
            for name, value in changed.items():
                hook = declared[name].on_change
                if hook is None:
                    continue
                fn = (
                    getattr(self.component, hook)
                    if isinstance(hook, str)
                    else functools.partial(hook, self.component)
                )
                await self._guarded(f"{name}.on_change", fn, value)
            await self._guarded("on_params_changed", self.component.on_params_changed, changed)
            ex = type(self.component).execution
            if isinstance(ex, Periodic) and ex.param in changed:
                rate = float(changed[ex.param])
                await self._guarded("on_rate_changed", self.component.on_rate_changed, rate)
            return changed

    async def step(self, n: int = 1) -> int:
        """Run `n` executions of a `Stepped` context now (`on_execute` while ACTIVE, `on_error`
        in ERROR), one after the other; how many ran `on_execute`. LifecycleError when the
        context is not Stepped or the component is neither ACTIVE nor in ERROR."""
        if not isinstance(type(self.component).execution, Stepped):
            raise LifecycleError("step", self._state.value, "its execution context is not Stepped")
        if n < 1:
            raise ValueError(f"step: n must be >= 1, got {n}")
        before = self.executions
        for _ in range(n):
            if self._state not in _RUNNING:
                raise LifecycleError("step", self._state.value, "it is not ACTIVE")
            await self._tick()
        return self.executions - before

    async def snapshot(self) -> Any:
        """`on_snapshot()`'s value (None without one); INACTIVE, ACTIVE or ERROR (handoff rules)."""
        async with self._lock:
            await self._settle()
            check_handoff("snapshot", self._state)
            return await call_snapshot(self.component)

    async def restore(self, state: Any) -> None:
        """Hand `state` to `on_restore`; INACTIVE or ACTIVE; CallbackError if it refuses."""
        async with self._lock:
            await self._settle()
            check_handoff("restore", self._state)
            await call_restore(self.component, state)

    # -- internals -------------------------------------------------------------------------

    def _set(self, state: LifecycleState, error: str | None = None) -> None:
        self._state = state
        if state is not S.ERROR:
            self.fault = None
        self._kick()
        for hook in tuple(self._state_hooks):
            try:
                hook(state, error)
            except Exception:
                self.component.log.exception("on_state hook failed")

    @staticmethod
    async def _call(fn: Callable[..., Any], *args: Any) -> None:
        result = fn(*args)
        if inspect.isawaitable(result):
            await result

    async def _guarded(self, name: str, fn: Callable[..., Any], *args: Any) -> None:
        """Run a callback; on failure go to ERROR (see `_fail`) and raise CallbackError."""
        try:
            await self._call(fn, *args)
        except Exception as exc:
            text = await self._fail(name, exc)
            raise CallbackError(name, text) from exc

    def _record(self, name: str, exc: Exception) -> str:
        text = f"{name}: {type(exc).__name__}: {exc}"
        self.component.last_error = text
        self.component.log.error("%s", text, exc_info=exc)
        return text

    async def _fail(self, name: str, exc: Exception) -> str:
        """Record the error, enter ERROR (hooks called at once), then run on_aborting."""
        text = self._record(name, exc)
        await self._enter_error(text, None)
        return text

    async def _enter_error(self, text: str, fault: str | None) -> None:
        was = self._state
        if was is not S.ERROR:
            self.fault = fault
            self._set(next_state(was, "error"), text)
            if was is S.ACTIVE:
                try:
                    await self._call(self.component.on_aborting)
                except Exception as abort_exc:
                    self.component.log.error("on_aborting failed", exc_info=abort_exc)

    async def _apply_fault(self) -> None:
        """A fault asks for ERROR: apply it as soon as the lock is free."""
        async with self._lock:
            await self._settle()

    async def _settle(self) -> None:
        """Apply a fault's pending move to ERROR (under the lock, before anything else)."""
        due = self._faults.take()
        if due is None or self._state in (S.ERROR, S.FINALIZED):
            return
        kind, text = due
        self.component.last_error = text
        await self._enter_error(text, kind)

    def _kick(self) -> None:
        w = self._waiter
        if w is not None and not w.done():
            w.set_result(None)

    def _on_input(self, frames: int) -> None:
        if self._state in _RUNNING:
            self._pending += frames
            self._kick()

    def _start(self) -> None:
        comp = type(self.component)
        if comp.on_execute is Component.on_execute and comp.on_error is Component.on_error:
            return  # nothing would ever run
        if isinstance(comp.execution, Stepped):
            return  # the caller runs it: `step`
        name = f"sdrpeer-exec-{self.component.instance_name}"
        self._task = asyncio.get_running_loop().create_task(self._run(), name=name)

    async def _wait(self, delay: float | None) -> None:
        loop = asyncio.get_running_loop()
        fut: asyncio.Future[None] = loop.create_future()
        self._waiter = fut
        handle = loop.call_later(delay, _wake, fut) if delay is not None else None
        try:
            await fut
        finally:
            self._waiter = None
            if handle is not None:
                handle.cancel()

    async def _tick(self) -> None:
        async with self._lock:
            if self._faults.pending is not None:
                await self._settle()
            state = self._state
            if state is S.ACTIVE:
                self.executions += 1
                try:
                    result = self.component.on_execute()
                    if inspect.isawaitable(result):
                        await result
                except Exception as exc:
                    await self._fail("on_execute", exc)
            elif state is S.ERROR:
                try:
                    await self._call(self.component.on_error)
                except Exception as exc:
                    if not self._on_error_failed:  # once per stay in ERROR: it runs every period
                        self._on_error_failed = True
                        self.component.log.error("on_error failed", exc_info=exc)

    async def _run(self) -> None:
        try:
            if self._input is not None:
                await self._run_on_input(self._input)
            else:
                ex = type(self.component).execution
                assert isinstance(ex, Periodic)
                await self._run_periodic(ex)
        except Exception:  # a bug in the runner: say so rather than die silently
            self.component.log.exception("execution context stopped")

    async def _run_on_input(self, port: InPortRuntime) -> None:
        while True:
            # Frames consumed meanwhile (read() consumes all queued) do not trigger again.
            self._pending = min(self._pending, port.qsize())
            if self._pending and self._state in _RUNNING:
                self._pending -= 1
                await self._tick()
            else:
                await self._wait(None)

    async def _run_periodic(self, ex: Periodic) -> None:
        loop = asyncio.get_running_loop()
        last: float | None = None  # when the previous execution was due
        while True:
            period = self._period(ex) if self._state in _RUNNING else None
            if period is None:
                last = None
                await self._wait(None)
                continue
            now = loop.time()
            if last is not None:
                due = last + period
                if due - now > _EARLY:
                    await self._wait(due - now)  # woken early on a state or rate change
                    continue
                last = due if now - due < period else now
            else:
                last = now
            await self._tick()

    def _period(self, ex: Periodic) -> float | None:
        if ex.hz is not None:
            return 1.0 / ex.hz
        assert ex.param is not None
        rate = self.component._param_values[ex.param]
        return 1.0 / rate if rate > 0 else None


def _same(a: object, b: object) -> bool:
    return type(a) is type(b) and a == b
