"""The stepped execution context and the execution-context callbacks: nothing runs until the
caller steps, a step runs exactly n executions, two stepped components make a deterministic
pipeline, `on_startup`/`on_shutdown` bracket the context, `on_rate_changed` follows a rate Param,
and a real host runs its component's steps on the `step` command."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from sdrpeer.sdk import (
    Component,
    ComponentRunner,
    InPort,
    LifecycleError,
    OnInput,
    OutPort,
    Param,
    Periodic,
    Stepped,
)
from tests.hostctl import HostPool


class Producer(Component):
    execution = Stepped()
    out = OutPort()

    def on_initialize(self) -> None:
        self.n = 0
        self.calls: list[str] = ["on_initialize"]

    def on_startup(self) -> None:
        self.calls.append("on_startup")

    def on_execute(self) -> None:
        self.n += 1
        self.out.write(self.n)

    def on_shutdown(self) -> None:
        self.calls.append("on_shutdown")

    def on_finalize(self) -> None:
        self.calls.append("on_finalize")


class Consumer(Component):
    execution = Stepped()
    inp = InPort(policy={"buffer": 100})

    def on_initialize(self) -> None:
        self.seen: list[Any] = []

    def on_execute(self) -> None:
        while self.inp.qsize():
            self.seen.append(self.inp.get_nowait())


class Sink:
    """An in-process connection: the producer's OutPort straight into the consumer's InPort."""

    def __init__(self, consumer: Consumer) -> None:
        self.port = consumer.inport("inp")
        self.seq = 0

    def offer(self, value: Any) -> bool:
        self.seq += 1
        self.port.deliver(value, self.seq, "c")
        return True


async def running(component: Component) -> ComponentRunner:
    runner = ComponentRunner(component)
    await runner.initialize()
    await runner.activate()
    return runner


async def test_nothing_runs_until_stepped_and_a_step_runs_exactly_n() -> None:
    producer, consumer = Producer(), Consumer()
    producer.outport("out").attach(Sink(consumer))
    p, c = await running(producer), await running(consumer)
    for _ in range(50):  # many loop turns: no clock, no input drives a stepped context
        await asyncio.sleep(0)
    assert p.executions == c.executions == 0
    assert await p.step(3) == 3
    assert await c.step() == 1
    assert consumer.seen == [1, 2, 3]
    assert await p.step(2) == 2
    assert consumer.seen == [1, 2, 3]  # the consumer has not been stepped since
    await c.step()
    assert consumer.seen == [1, 2, 3, 4, 5]
    await p.deactivate()
    with pytest.raises(LifecycleError, match="cannot step: component is INACTIVE"):
        await p.step()
    await p.finalize()
    await c.finalize()
    assert producer.calls == ["on_initialize", "on_startup", "on_shutdown", "on_finalize"]


class Paced(Component):
    execution = Periodic(param="rate")
    rate = Param(float, 0.0, "executions per second (0: paused)")
    gain = Param(float, 1.0, "not a rate")

    def on_initialize(self) -> None:
        self.rates: list[float] = []

    def on_rate_changed(self, hz: float) -> None:
        self.rates.append(hz)


async def test_rate_changes_are_told_and_a_periodic_context_cannot_be_stepped() -> None:
    paced = Paced()
    runner = await running(paced)
    await runner.set_params({"rate": 5.0})
    await runner.set_params({"gain": 2.0})  # another param: no rate change
    await runner.set_params({"rate": 5.0})  # the same rate: nothing changed
    await runner.set_params({"rate": 0.0})
    assert paced.rates == [5.0, 0.0]
    with pytest.raises(LifecycleError, match="its execution context is not Stepped"):
        await runner.step()
    await runner.finalize()


def test_an_on_input_class_is_still_checked() -> None:
    with pytest.raises(Exception, match="names no InPort"):

        class Bad(Component):
            execution = OnInput("missing")


def test_a_hosted_stepped_component_runs_on_the_step_command(hosts: HostPool) -> None:
    host, _ = hosts.ready("tests.stepped_fixture:SteppedCounter", name="Steps")
    assert host.command("activate")["ok"] is True
    assert host.command("step", n=5)["ok"] is True
    assert host.command("step", n=0)["error"] == "'n': expected an integer >= 1"
    beat = host.wait_for(  # heartbeats queued before the steps may come first: read on
        lambda m: m["t"] == "heartbeat" and m["ports"]["out"]["frames_out"] >= 5, what="5 out"
    )
    assert beat["ports"]["out"]["frames_out"] == 5  # five steps, five writes, none on its own
    assert host.command("deactivate")["ok"] is True
    refused = host.command("step")
    assert refused["ok"] is False
    assert "cannot step: component is INACTIVE" in refused["error"]
    assert host.command("exit")["ok"] is True
    assert host.wait_exit() == 0


class Flaky(Component):
    execution = Stepped()

    def on_initialize(self) -> None:
        self.calls: list[str] = getattr(self, "calls", [])
        self.calls.append("on_initialize")

    def on_startup(self) -> None:
        self.calls.append("on_startup")
        if self.calls.count("on_startup") == 1:
            raise RuntimeError("the context would not start")

    def on_shutdown(self) -> None:
        self.calls.append("on_shutdown")

    def on_finalize(self) -> None:
        self.calls.append("on_finalize")


async def test_a_failed_startup_is_retried_by_reset_and_shutdown_only_follows_a_startup() -> None:
    flaky = Flaky()
    runner = ComponentRunner(flaky)
    with pytest.raises(Exception, match="on_startup"):
        await runner.initialize()
    await runner.reset()  # on_initialize succeeded: not again; on_startup is owed
    assert flaky.calls == ["on_initialize", "on_startup", "on_startup"]
    await runner.finalize()
    assert flaky.calls[-2:] == ["on_shutdown", "on_finalize"]
    never = Flaky()
    runner = ComponentRunner(never)
    with pytest.raises(Exception, match="on_startup"):
        await runner.initialize()
    await runner.finalize()  # the context never started: no on_shutdown
    assert never.calls == ["on_initialize", "on_startup", "on_finalize"]
