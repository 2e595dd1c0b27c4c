"""Bounded waits for tests: wait until a condition holds, or watch that one keeps holding.

How it works: every helper polls a `probe` (a call that returns the value to judge, such as a
state, a count or an HTTP answer) and judges each value with `ok` (truthiness by default).
`until` returns the first value `ok` accepts and fails after `within` seconds; `stays` is the
opposite test, for the few behaviours that are the absence of an event ("nothing is restarted
while ..."): it polls throughout an explicit `window` and fails at once, with the time it held,
when `ok` turns false. Failures are `WaitError` (an AssertionError, so pytest shows them as a
test failure) naming what was awaited, the time waited and the last value seen.

The `*_async` forms run on the event loop, sleep with `asyncio.sleep` and measure the window on the
loop's clock, so they also work on `tests.virtual_time` loops; `until_async` takes a plain probe,
`until_answer` an async one (an HTTP call). The synchronous forms are for tests that drive
processes from the test thread.

Every wait is bounded in time (`within` or `window`) and hence in polls (one per `poll` s). A
probe that raises one of the `retry` exceptions counts as "not yet" (an agent that is still
starting refuses connections); any other exception propagates at once.
"""

from __future__ import annotations

import asyncio
import time
from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

T = TypeVar("T")

WITHIN = 10.0
"""Default bound of `until` (s): long enough for a loaded 2-core machine, never reached when the
code works."""
POLL = 0.02
"""Default time between two probes (s) that cost something (a request, a file read)."""
POLL_ATTR = 0.005
"""Default time between two probes of plain attributes on the event loop (s): cheap to look at,
and the test goes on as soon as the condition holds."""
SHOWN = 1200
"""How many characters of the last value a failure message shows (its start and its end)."""


class WaitError(AssertionError):
    """A bounded wait ran out, or a condition that had to keep holding turned."""


def _never_failed() -> str | None:
    return None


def _nothing() -> str:
    return ""


def _last(value: Any) -> str:
    text = repr(value)
    if len(text) <= SHOWN:
        return text
    return f"{text[: SHOWN // 2]} ... {text[-SHOWN // 2 :]}"


def _describe(
    what: str, verb: str, seconds: float, last: Any, context: Callable[[], str]
) -> WaitError:
    extra = context()
    return WaitError(
        f"{verb} {seconds:.2f} s for {what}; last seen: {_last(last)}"
        + (f"\n{extra}" if extra else "")
    )


def until(
    what: str,
    probe: Callable[[], T],
    ok: Callable[[T], object] = bool,
    *,
    within: float = WITHIN,
    poll: float = POLL,
    retry: tuple[type[Exception], ...] = (),
    abort: Callable[[], str | None] = _never_failed,
    context: Callable[[], str] = _nothing,
) -> T:
    """The first value of `probe()` that `ok` accepts; WaitError naming `what` after `within` s.

    `abort()` returning a reason (a process died) fails the wait at once; `context()` is appended
    to a failure message (logs)."""
    start = time.monotonic()
    last: Any = "(no answer yet)"
    while True:
        try:
            value = probe()
        except retry as exc:
            last = f"{type(exc).__name__}: {exc}"
        else:
            if ok(value):
                return value
            last = value
        waited = time.monotonic() - start
        if waited >= within:
            raise _describe(what, "waited", waited, last, context)
        reason = abort()
        if reason is not None:
            raise _describe(what, f"gave up ({reason}) after", waited, last, context)
        time.sleep(min(poll, max(0.0, within - waited)))


def _broke(what: str, held: float, window: float, value: object) -> WaitError:
    return WaitError(
        f"{what} stopped holding after {held:.2f} s of a {window:g} s window; value: {_last(value)}"
    )


def stays(
    what: str,
    probe: Callable[[], T],
    ok: Callable[[T], object] = bool,
    *,
    window: float,
    poll: float = POLL,
) -> T:
    """Check that `ok(probe())` holds throughout `window` s (polled every `poll` s, first and last
    at the window's ends); WaitError as soon as it does not. The last value seen."""
    start = time.monotonic()
    while True:
        value = probe()
        held = time.monotonic() - start
        if not ok(value):
            raise _broke(what, held, window, value)
        if held >= window:
            return value
        time.sleep(min(poll, window - held))


async def until_answer(
    what: str,
    probe: Callable[[], Awaitable[T]],
    ok: Callable[[T], object] = bool,
    *,
    within: float = WITHIN,
    poll: float = POLL,
    retry: tuple[type[Exception], ...] = (),
) -> T:
    """`until` on the event loop for an async `probe` (its time counts against `within`)."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    last: Any = "(no answer yet)"
    while True:
        try:
            value = await probe()
        except retry as exc:
            last = f"{type(exc).__name__}: {exc}"
        else:
            if ok(value):
                return value
            last = value
        waited = loop.time() - start
        if waited >= within:
            raise _describe(what, "waited", waited, last, _nothing)
        await asyncio.sleep(min(poll, max(0.0, within - waited)))


async def until_async(
    what: str,
    probe: Callable[[], T],
    ok: Callable[[T], object] = bool,
    *,
    within: float = WITHIN,
    poll: float = POLL_ATTR,
) -> T:
    """`until` on the event loop: the other tasks run while it waits."""

    async def answer() -> T:
        return probe()

    return await until_answer(what, answer, ok, within=within, poll=poll)


async def stays_async(
    what: str,
    probe: Callable[[], T],
    ok: Callable[[T], object] = bool,
    *,
    window: float,
    poll: float = POLL_ATTR,
) -> T:
    """`stays` on the event loop (the window on the loop's clock: virtual under
    `tests.virtual_time`)."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    while True:
        value = probe()
        held = loop.time() - start
        if not ok(value):
            raise _broke(what, held, window, value)
        if held >= window:
            return value
        await asyncio.sleep(min(poll, window - held))
