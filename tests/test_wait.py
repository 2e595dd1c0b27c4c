"""tests/wait.py: the bounded waits every test uses say what they awaited and what they saw."""

from __future__ import annotations

import asyncio
import itertools
import time

import pytest

from tests.virtual_time import run_virtual
from tests.wait import WaitError, stays, stays_async, until, until_answer, until_async


def test_until_returns_the_first_accepted_value() -> None:
    count = itertools.count()
    assert until("three", lambda: next(count), lambda n: n >= 3, poll=0.001) == 3


def test_until_fails_after_its_bound_naming_what_and_the_last_value() -> None:
    began = time.monotonic()
    with pytest.raises(WaitError, match=r"waited 0\.\d\d s for the answer; last seen: 41") as err:
        until("the answer", lambda: 41, lambda n: n == 42, within=0.05, poll=0.01)
    assert 0.05 <= time.monotonic() - began < 2.0
    assert isinstance(err.value, AssertionError)


def test_until_counts_a_retry_exception_as_not_yet_and_shows_it() -> None:
    calls = itertools.count()

    def probe() -> int:
        if next(calls) < 2:
            raise ConnectionRefusedError("not listening")
        return 7

    assert until("an answer", probe, retry=(OSError,), poll=0.001) == 7

    def refuses() -> int:
        raise ConnectionRefusedError("not listening")

    with pytest.raises(WaitError, match="last seen: 'ConnectionRefusedError: not listening'"):
        until("an answer", refuses, retry=(OSError,), within=0.02, poll=0.005)
    with pytest.raises(ConnectionRefusedError):  # not a retry exception: at once
        until("an answer", refuses, within=5)


def test_until_aborts_at_once_and_appends_the_context() -> None:
    began = time.monotonic()
    with pytest.raises(WaitError, match=r"gave up \(robot-1 exited\)[\s\S]*the log tail"):
        until(
            "convergence",
            lambda: False,
            within=10,
            abort=lambda: "robot-1 exited",
            context=lambda: "the log tail",
        )
    assert time.monotonic() - began < 5.0


def test_stays_watches_the_whole_window_and_fails_when_it_turns() -> None:
    began = time.monotonic()
    assert stays("quiet", lambda: 0, lambda n: n == 0, window=0.05, poll=0.01) == 0
    assert time.monotonic() - began >= 0.05
    count = itertools.count()
    with pytest.raises(WaitError, match=r"below 3 stopped holding after .* value: 3"):
        stays("below 3", lambda: next(count), lambda n: n < 3, window=10, poll=0.001)
    assert time.monotonic() - began < 5.0  # failed at once, not at the window's end


def test_the_async_forms_use_the_loops_clock() -> None:
    """On virtual time (tests/virtual_time.py) the bounds are exact and take no wall time."""

    async def scenario() -> None:
        loop = asyncio.get_running_loop()
        flag: list[int] = []
        loop.call_later(0.5, flag.append, 1)
        assert await until_async("the flag", lambda: flag) == [1]
        assert loop.time() == pytest.approx(0.5, abs=0.03)
        with pytest.raises(WaitError, match=r"waited 2\.00 s for never; last seen: \[1\]"):
            await until_async("never", lambda: flag, lambda f: len(f) == 2, within=2.0)
        start = loop.time()
        await stays_async("one flag", lambda: flag, lambda f: len(f) == 1, window=3.0)
        assert loop.time() - start == pytest.approx(3.0)
        loop.call_later(1.0, flag.append, 2)
        with pytest.raises(WaitError, match=r"stopped holding after 1\.0\d s of a 5 s window"):
            await stays_async("one flag", lambda: flag, lambda f: len(f) == 1, window=5.0)

        async def answer() -> int:
            await asyncio.sleep(0.1)
            return len(flag)

        assert await until_answer("two", answer, lambda n: n == 2) == 2

    run_virtual(scenario())


def test_a_long_last_value_shows_its_start_and_its_end() -> None:
    log = "started\n" + "x" * 5000 + "\nthe error at the end"
    with pytest.raises(WaitError) as err:
        until("'ready' in the log", lambda: log, lambda text: "ready" in text, within=0)
    message = str(err.value)
    assert "'started" in message
    assert "the error at the end'" in message
    assert len(message) < 1400
