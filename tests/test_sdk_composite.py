"""Composite components (sdrpeer.sdk.composite): the members' callbacks run in execution order
(deactivate and finalize in reverse), ports and params are the members' as `Member.name`, one
member's failure or fault puts the whole composite in ERROR naming the member, a stepped
composite is a deterministic pipeline, and snapshot/restore carry a map of member states."""

from __future__ import annotations

import asyncio
from collections.abc import Iterator
from typing import Any

import pytest

from sdrpeer.sdk import (
    CallbackError,
    ComponentError,
    ComponentRunner,
    LifecycleState,
    ParamError,
    Periodic,
    Stepped,
)
from sdrpeer.sdk.composite import Composite, composite_class
from tests.composite_fixture import Alarm, Doubler, Journaled, Sink, Source, Stuck

S = LifecycleState


@pytest.fixture(autouse=True)
def journal() -> Iterator[list[str]]:
    Journaled.JOURNAL.clear()
    yield Journaled.JOURNAL
    Journaled.JOURNAL.clear()


class Wire:
    """An in-process connection: one runtime OutPort straight into one runtime InPort."""

    def __init__(self, comp: Composite, out: str, inp: str) -> None:
        self.port = comp.inport(inp)
        self.seq = 0
        comp.outport(out).attach(self)

    def offer(self, value: Any) -> bool:
        self.seq += 1
        self.port.deliver(value, self.seq, "w")
        return True


class Tap:
    """Sets `event` once it has been offered `count` values."""

    def __init__(self, event: asyncio.Event, count: int) -> None:
        self.event, self.count = event, count

    def offer(self, value: Any) -> bool:
        self.count -= 1
        if self.count <= 0:
            self.event.set()
        return True


def pipeline(execution: Periodic | Stepped | None = None) -> Composite:
    """Src -> Dbl -> Out, wired inside one composite (as connections would wire it)."""
    cls = composite_class(
        "Pipe",
        [("Src", Source), ("Dbl", Doubler), ("Out", Sink)],
        execution or Stepped(),
    )
    comp = cls(name="Pipe", params={"Src.step": "1"})
    Wire(comp, "Src.out", "Dbl.inp")
    Wire(comp, "Dbl.out", "Out.inp")
    return comp


def values(comp: Composite) -> list[Any]:
    sink = comp.parts["Out"]
    assert isinstance(sink, Sink)
    return sink.values


async def test_callbacks_run_in_member_order_and_deactivate_in_reverse(journal: list[str]) -> None:
    comp = pipeline()
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    assert journal == [
        "Source.on_initialize",
        "Doubler.on_initialize",
        "Sink.on_initialize",
        "Source.on_startup",
        "Doubler.on_startup",
        "Sink.on_startup",
        "Source.on_activated",
        "Doubler.on_activated",
        "Sink.on_activated",
    ]
    journal.clear()
    assert await runner.step(1) == 1
    assert journal == ["Source.on_execute", "Doubler.on_execute", "Sink.on_execute"]
    journal.clear()
    await runner.finalize()
    assert journal == [
        "Sink.on_deactivated",
        "Doubler.on_deactivated",
        "Source.on_deactivated",
        "Sink.on_shutdown",
        "Doubler.on_shutdown",
        "Source.on_shutdown",
        "Sink.on_finalize",
        "Doubler.on_finalize",
        "Source.on_finalize",
    ]


async def test_a_stepped_composite_is_a_deterministic_pipeline() -> None:
    comp = pipeline()
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    for _ in range(20):  # no clock drives a stepped composite
        await asyncio.sleep(0)
    assert values(comp) == []
    await runner.step(3)
    # in order: each step's value goes through the whole pipeline within that step
    assert values(comp) == [2, 4, 6]
    await runner.finalize()


async def test_a_periodic_composite_runs_every_member_each_period() -> None:
    comp = pipeline(Periodic(hz=200.0))
    tenth = asyncio.Event()
    comp.outport("Dbl.out").attach(Tap(tenth, 10))
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    async with asyncio.timeout(5.0):
        await tenth.wait()
    await runner.deactivate()  # one more period at most: Out takes what Dbl wrote
    await runner.finalize()
    got = values(comp)
    assert got[:10] == [2 * i for i in range(1, 11)]  # nothing lost, nothing reordered


async def test_ports_and_params_are_the_members_as_member_dot_name() -> None:
    comp = pipeline()
    assert type(comp).port_names() == {
        "in": ["Dbl.inp", "Out.inp"],
        "out": ["Src.out", "Dbl.out"],
    }
    assert comp.outport("Src.out") is comp.parts["Src"].outport("out")
    assert comp.param_values() == {"Src.step": 1, "Dbl.fail_at": 0, "Dbl.gain": 2}
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    changed = await runner.set_params({"Dbl.gain": "3", "Src.step": 2})
    assert changed == {"Dbl.gain": 3, "Src.step": 2}
    dbl = comp.parts["Dbl"]
    assert isinstance(dbl, Doubler)
    assert dbl.gain == 3  # the member's own value
    assert dbl.gains == [3]  # and its on_change hook ran
    await runner.step(1)
    assert values(comp) == [6]  # step 2, gain 3
    with pytest.raises(ParamError, match=r"Dbl\.nope"):
        await runner.set_params({"Dbl.nope": 1})
    with pytest.raises(ParamError, match="unknown param"):
        type(comp)(params={"Ghost.x": 1})
    with pytest.raises(ParamError, match=r"param 'Dbl\.nope': unknown param \(known: Src\.step"):
        type(comp)(params={"Dbl.nope": 1})
    await runner.finalize()


async def test_one_member_failing_puts_the_composite_in_error_naming_it(
    journal: list[str],
) -> None:
    comp = pipeline()
    runner = ComponentRunner(comp)
    states: list[tuple[S, str | None]] = []
    runner.on_state(lambda s, e: states.append((s, e)))
    await runner.set_params({"Dbl.fail_at": 2})
    await runner.initialize()
    await runner.activate()
    await runner.step(1)
    journal.clear()
    await runner.step(1)  # Source writes 2: Doubler raises, Sink does not run
    assert runner.state is S.ERROR
    error = states[-1][1]
    assert error is not None
    assert "member Dbl: on_execute: ValueError: cannot double 2" in error
    assert comp.member_errors()["Dbl"] is not None
    assert comp.member_errors()["Src"] is None
    assert journal == [
        "Source.on_execute",
        "Doubler.on_execute",
        "Sink.on_aborting",
        "Doubler.on_aborting",
        "Source.on_aborting",
    ]
    await runner.set_params({"Dbl.fail_at": 0})
    await runner.reset()
    assert states[-1] == (S.INACTIVE, None)
    await runner.finalize()


async def test_an_activation_failing_part_way_undoes_the_members_already_active(
    journal: list[str],
) -> None:
    cls = composite_class("C", [("A", Source), ("B", Stuck), ("Z", Sink)], Stepped())
    runner = ComponentRunner(cls())
    await runner.initialize()
    journal.clear()
    with pytest.raises(CallbackError, match="member B: on_activated: RuntimeError"):
        await runner.activate()
    assert runner.state is S.ERROR
    assert journal == ["Source.on_activated", "Stuck.on_activated", "Source.on_deactivated"]
    await runner.finalize()


async def test_a_members_fault_is_the_composites_with_the_member_named() -> None:
    cls = composite_class("C", [("Src", Source), ("Bumper", Alarm)], Stepped())
    runner = ComponentRunner(cls())
    faults: list[tuple[str, str]] = []
    runner.on_fault(lambda kind, detail: faults.append((kind, detail)))
    error = asyncio.Event()
    runner.on_state(lambda state, _: error.set() if state is S.ERROR else None)
    await runner.initialize()
    await runner.activate()
    await runner.step(1)
    async with asyncio.timeout(2.0):
        await error.wait()
    assert faults == [("emergency_stop", "Bumper: bumper pressed")]
    assert runner.fault == "emergency_stop"
    await runner.finalize()


async def test_snapshot_and_restore_carry_a_map_of_member_errors() -> None:
    comp = pipeline()
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    await runner.step(4)
    state = await runner.snapshot()
    assert state == {"Src": {"n": 4}}  # the others keep no state
    fresh = pipeline()
    again = ComponentRunner(fresh)
    await again.initialize()
    with pytest.raises(CallbackError, match="no member 'Ghost'"):
        await again.restore({"Ghost": 1, "Src": {"n": 100}})
    with pytest.raises(CallbackError, match="member Out has no on_restore"):
        await again.restore({"Out": [1], "Src": {"n": 100}})
    assert fresh.parts["Src"].n == 0  # type: ignore[attr-defined]  # refused whole
    await again.restore(state)
    await again.activate()
    await again.step(1)
    assert values(fresh) == [10]  # continues from 4
    await runner.finalize()
    await again.finalize()


def test_a_composite_is_checked_when_it_is_built() -> None:
    with pytest.raises(ComponentError, match="no members"):
        composite_class("C", [], Stepped())
    with pytest.raises(ComponentError, match="given twice"):
        composite_class("C", [("A", Source), ("A", Sink)], Stepped())
    with pytest.raises(ComponentError, match="fixed hz"):
        composite_class("C", [("A", Source)], Periodic(param="rate"))
    inner = composite_class("In", [("A", Source)], Stepped())
    with pytest.raises(ComponentError, match="do not nest"):
        composite_class("C", [("A", inner)], Stepped())
    with pytest.raises(ComponentError, match="not an identifier"):
        composite_class("C", [("A.b", Source)], Stepped())
    from components.planner import PathPlanner  # noqa: PLC0415 - only this check needs it

    with pytest.raises(ComponentError, match="declares service ports \\(planner\\)"):
        composite_class("C", [("A", Source), ("P", PathPlanner)], Stepped())
