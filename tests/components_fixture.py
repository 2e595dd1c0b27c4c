"""Small components the host tests run: a publisher, a recorder, a crasher, one with params,
fault reporters, ones with a state to hand over, a service provider and its caller."""

from __future__ import annotations

import asyncio
import contextlib
import os
import threading
import time
from typing import Any

from sdrpeer.sdk import (
    Component,
    InPort,
    Interface,
    OnInput,
    OutPort,
    Param,
    Periodic,
    ServiceCallError,
    ServiceConsumer,
    ServiceProvider,
    Stepped,
)


class Counter(Component):
    """Publishes 1, 2, 3, ... on `out` at `rate` Hz."""

    execution = Periodic(param="rate")
    rate = Param(float, 100.0, "frames per second")
    out = OutPort("the count")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_execute(self) -> None:
        """Publish the next number."""
        self.n += 1
        self.out.write(self.n)


class Recorder(Component):
    """Records every value arriving on `inp`; logs how many it has at deactivation."""

    execution = OnInput("inp")
    inp = InPort("anything")

    def on_initialize(self) -> None:
        """Start with nothing."""
        self.values: list[Any] = []

    def on_execute(self) -> None:
        """Keep what arrived."""
        while self.inp.qsize():
            self.values.append(self.inp.get_nowait())

    def on_deactivated(self) -> None:
        """Say what arrived."""
        self.log.info("recorded %d values, last %r", len(self.values), self.values[-1:])


class Crasher(Component):
    """Raises in `on_execute` after `after` periods, writing the time of the raise to `stamp`."""

    execution = Periodic(hz=200.0)
    after = Param(int, 5, "periods before the raise")
    stamp = Param(str, "", "file that gets time.time() just before the raise")

    def on_activated(self) -> None:
        """Count from zero."""
        self.count = 0

    def on_execute(self) -> None:
        """Raise on the `after`-th period."""
        self.count += 1
        if self.count == self.after:
            if self.stamp:
                with open(self.stamp + ".tmp", "w") as f:
                    f.write(repr(time.time()))
                os.replace(self.stamp + ".tmp", self.stamp)
            raise RuntimeError(f"crash after {self.after} periods")


class Tunable(Component):
    """Params of every type; logs each change so a test can see it."""

    gain = Param(float, 1.0, "a number", min=0.0, max=10.0)
    mode = Param(str, "fast", "a choice", choices=["fast", "slow"])
    enabled = Param(bool, True, "a switch")
    count = Param(int, 3, "a whole number")
    out = OutPort("the gain")

    def on_params_changed(self, changed: dict[str, Any]) -> None:
        """Log the change and publish the gain."""
        self.log.info("params changed: %s", sorted(changed.items()))
        self.out.write(self.gain)


class Faulty(Component):
    """Reports a fault when activated."""

    def on_activated(self) -> None:
        """Report overheating."""
        self.report_fault("hardware_failure", "motor 2 overheated")


class Reporter(Component):
    """Reports the faults in `kinds` (comma-separated) when activated, from a thread if `thread`."""

    kinds = Param(str, "", "fault kinds, e.g. emergency_stop,abnormal_behaviour")
    thread = Param(bool, False, "report from a thread the component starts")

    def on_activated(self) -> None:
        """Report each kind, its detail saying which one it is (#0, #1, ...)."""
        kinds = [k for k in self.kinds.split(",") if k]

        def report() -> None:
            for i, kind in enumerate(kinds):
                self.report_fault(kind, f"#{i}")

        if self.thread:
            threading.Thread(target=report, name="reporter").start()
        else:
            report()


class Hoarder(Component):
    """Keeps `kb` KiB of state: `on_snapshot` returns it, `on_restore` takes `{"blob": bytes}`."""

    kb = Param(int, 1, "KiB of state", min=0)

    def on_initialize(self) -> None:
        """Make the state."""
        self.blob = bytes(range(256)) * (self.kb * 4)

    def on_snapshot(self) -> dict[str, Any]:
        """The state."""
        return {"blob": self.blob}

    def on_restore(self, state: Any) -> None:
        """Take a state over; ValueError unless it is `{"blob": bytes}`."""
        if not isinstance(state, dict) or not isinstance(state.get("blob"), bytes):
            raise ValueError(f"expected {{'blob': bytes}}, got {type(state).__name__}")
        self.blob = state["blob"]


class Tally(Component):
    """Counts at `rate` Hz and publishes the count; its state is the count, and every restore and
    activation is logged (`restored n=...`, `active from n=...`) so a test can follow it."""

    execution = Periodic(param="rate")
    rate = Param(float, 20.0, "counts per second")
    out = OutPort("the count")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_activated(self) -> None:
        """Say where counting goes on from."""
        self.log.info("active from n=%d", self.n)

    def on_execute(self) -> None:
        """Count and publish."""
        self.n += 1
        self.out.write(self.n)

    def on_snapshot(self) -> dict[str, int]:
        """The count."""
        return {"n": self.n}

    def on_restore(self, state: Any) -> None:
        """Go on from a predecessor's count."""
        if not isinstance(state, dict) or not isinstance(state.get("n"), int):
            raise ValueError(f"expected {{'n': int}}, got {state!r}")
        self.n = state["n"]
        self.log.info("restored n=%d", self.n)


class Fragile(Component):
    """Raises in `on_execute` while the file `trigger` names this instance (one name a line)."""

    execution = Periodic(hz=50.0)
    trigger = Param(str, "", "a file; an instance named in it raises")

    def on_execute(self) -> None:
        """Raise if named."""
        if self.trigger and os.path.exists(self.trigger):
            with open(self.trigger) as f:
                if self.instance_name in f.read().split():
                    raise RuntimeError(f"{self.instance_name} was told to fail")


class Stubborn(Component):
    """Will not stop: its on_finalize never returns, and it ignores SIGTERM."""

    execution = Periodic(hz=10.0)

    def on_initialize(self) -> None:
        """Ignore SIGTERM (only SIGKILL ends this host)."""
        import signal  # noqa: PLC0415 - only this fixture needs it

        signal.signal(signal.SIGTERM, signal.SIG_IGN)

    def on_execute(self) -> None:
        """Nothing."""

    def on_finalize(self) -> None:
        """Hang."""
        while True:
            time.sleep(1.0)


class Sleeper(Component):
    """Counts on `out` at 20 Hz; blocks for good inside `on_execute` once the file `trigger`
    names this instance (a component stuck in a call that never returns)."""

    execution = Periodic(hz=20.0)
    trigger = Param(str, "", "a file; an instance named in it blocks")
    out = OutPort("the count")

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_execute(self) -> None:
        """Publish, or block when named."""
        if self.trigger and os.path.exists(self.trigger):
            with open(self.trigger) as f:
                if self.instance_name in f.read().split():
                    while True:
                        time.sleep(1.0)
        self.n += 1
        self.out.write(self.n)


class Laggard(Component):
    """Takes one value from `inp` every 1/`rate` s, whatever arrives (a consumer slower than
    its producer); keeps how many it took."""

    execution = Periodic(param="rate")
    rate = Param(float, 20.0, "values taken per second")
    inp = InPort("anything")

    def on_initialize(self) -> None:
        """Nothing taken yet."""
        self.taken = 0

    def on_execute(self) -> None:
        """Take the oldest value waiting, if any."""
        if self.inp.qsize():
            self.inp.get_nowait()
            self.taken += 1


ECHO = Interface.of("test/Echo", "echo", "boom", "slow")
"""The fixture service: `echo` returns its argument, `boom` raises, `slow` sleeps first."""
OTHER_ECHO = Interface.of("test/Echo", "echo", "boom")
"""Same name, other methods: another interface id (a consumer of it is refused)."""


class EchoService(Component):
    """Provides `ECHO` on `svc` (stepped: it only answers calls)."""

    execution = Stepped()
    svc = ServiceProvider(ECHO, "echoes")

    @svc.method
    def echo(self, arg: Any) -> Any:
        """`arg`, unchanged."""
        return arg

    @svc.method
    def boom(self, arg: Any) -> Any:
        """Always raises ValueError(arg)."""
        raise ValueError(str(arg))

    @svc.method
    async def slow(self, seconds: float) -> float:
        """Answers `seconds` after that many seconds."""
        await asyncio.sleep(seconds)
        return seconds


class EchoCaller(Component):
    """Calls `method` of `ECHO` every period (`echo` with its call number, `boom`, or `slow` for
    one second); `other` requires `OTHER_ECHO` and calls it too once bound."""

    execution = Periodic(param="rate")
    rate = Param(float, 20.0, "calls per second")
    method = Param(str, "echo", "echo, boom or slow")
    svc = ServiceConsumer(ECHO, "the echo it calls")
    other = ServiceConsumer(OTHER_ECHO, "a mismatched interface")
    out = OutPort("each echoed number")

    def on_initialize(self) -> None:
        """No call yet."""
        self.n = 0

    async def on_execute(self) -> None:
        """One call; an echo's reply goes out on `out` (the port counts failures by kind)."""
        self.n += 1
        method = self.param_values()["method"]
        with contextlib.suppress(ServiceCallError):
            reply = await self.svc.call(method, 1.0 if method == "slow" else self.n, timeout=0.3)
            self.out.write(reply)
        if self.other.link is not None:
            with contextlib.suppress(ServiceCallError):
                await self.other.call("echo", self.n, timeout=0.5)
