"""Faults a component reports (sdrpeer.sdk.faults): the table, hooks, ERROR moves, threads; and
end to end, real hosts under the agent's InstanceManager: its on_fault and on_instance_problem
hooks (component_error, crashed)."""

from __future__ import annotations

import asyncio
import os
import signal
import threading
from collections.abc import AsyncIterator
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.sdk import (
    FAULT_EFFECTS,
    FAULT_KINDS,
    Component,
    ComponentRunner,
    FaultEffect,
    LifecycleState,
    Periodic,
)
from sdrpeer.sdk.faults import moves_to_error
from tests.wait import stays_async, until_async

S = LifecycleState


class Robot(Component):
    """Reports the fault named in `fault_on_execute` from its next on_execute; records callbacks."""

    execution = Periodic(hz=200.0)

    def __init__(self, name: str | None = None) -> None:
        super().__init__(name)
        self.calls: list[str] = []
        self.fault_on_execute: tuple[str, str] | None = None
        self.fault_on_initialize: tuple[str, str] | None = None

    def on_initialize(self) -> None:
        self.calls.append("on_initialize")
        if self.fault_on_initialize is not None:
            self.report_fault(*self.fault_on_initialize)

    def on_execute(self) -> None:
        self.calls.append("on_execute")
        fault, self.fault_on_execute = self.fault_on_execute, None
        if fault is not None:
            self.report_fault(*fault)
            self.calls.append("after report")

    def on_aborting(self) -> None:
        self.calls.append("on_aborting")

    def on_reset(self) -> None:
        self.calls.append("on_reset")

    def on_finalize(self) -> None:
        self.calls.append("on_finalize")


class AsyncRobot(Robot):
    """Reports from an async on_execute, across an await."""

    async def on_execute(self) -> None:  # type: ignore[override]
        self.calls.append("on_execute")
        fault, self.fault_on_execute = self.fault_on_execute, None
        if fault is not None:
            await asyncio.sleep(0)
            self.report_fault(*fault)
            await asyncio.sleep(0.01)
            self.calls.append("after report")


@pytest.fixture
async def runner() -> AsyncIterator[ComponentRunner]:
    r = ComponentRunner(Robot("bot"))
    yield r
    if r.state is not S.FINALIZED:
        await r.finalize()


def bot(r: ComponentRunner) -> Robot:
    assert isinstance(r.component, Robot)
    return r.component


def state_of(r: ComponentRunner) -> LifecycleState:
    return r.state


def fault_of(r: ComponentRunner) -> str | None:
    return r.fault


def record(r: ComponentRunner) -> tuple[list[tuple[str, str]], list[tuple[S, str | None, Any]]]:
    faults: list[tuple[str, str]] = []
    states: list[tuple[S, str | None, Any]] = []
    r.on_fault(lambda k, d: faults.append((k, d)))
    r.on_state(lambda s, e: states.append((s, e, r.fault)))
    return faults, states


@pytest.mark.parametrize(
    ("kind", "effect"),
    [
        ("hardware_failure", FaultEffect.ERROR),
        ("emergency_stop", FaultEffect.ERROR),
        ("abnormal_behaviour", FaultEffect.REPORT),
    ],
)
def test_the_effect_table(kind: str, effect: FaultEffect) -> None:
    assert FAULT_EFFECTS[kind] is effect
    assert moves_to_error(kind) is (effect is FaultEffect.ERROR)
    assert kind in FAULT_KINDS


def test_unknown_kind_is_refused_in_the_caller() -> None:
    with pytest.raises(ValueError, match=r"kind 'overheat' not in hardware_failure, "):
        Robot().report_fault("overheat")
    assert not moves_to_error("overheat")


def test_shorthands_without_a_runner_only_log(caplog: pytest.LogCaptureFixture) -> None:
    comp = Robot("lonely")
    comp.hardware_failure("camera unplugged")
    comp.abnormal_behaviour("wheel slip")
    comp.emergency_stop()
    text = caplog.text
    assert "fault hardware_failure: camera unplugged" in text
    assert "fault abnormal_behaviour: wheel slip" in text
    assert "fault emergency_stop" in text


@pytest.mark.parametrize("cls", [Robot, AsyncRobot])
async def test_emergency_stop_from_on_execute_reports_at_once_then_errors_through_aborting(
    cls: type[Robot],
) -> None:
    r = ComponentRunner(cls("bot"))
    faults, states = record(r)
    await r.initialize()
    await r.activate()
    bot(r).fault_on_execute = ("emergency_stop", "bumper pressed")
    await until_async("the fault", lambda: faults)
    assert faults == [("emergency_stop", "bumper pressed")]
    await until_async("ERROR", lambda: state_of(r), lambda s: s is S.ERROR)
    assert states[-1] == (S.ERROR, "emergency_stop: bumper pressed", "emergency_stop")
    assert r.fault == "emergency_stop"
    assert r.last_error == "emergency_stop: bumper pressed"
    calls = bot(r).calls
    # The callback that reported ran to its end before on_aborting: callbacks never interleave.
    assert calls.index("after report") < calls.index("on_aborting")
    assert calls.count("on_aborting") == 1
    await r.reset()
    assert (state_of(r), r.last_error is not None, fault_of(r)) == (S.INACTIVE, True, None)
    await r.finalize()


async def test_abnormal_behaviour_only_reports(runner: ComponentRunner) -> None:
    faults, states = record(runner)
    await runner.initialize()
    await runner.activate()
    bot(runner).fault_on_execute = ("abnormal_behaviour", "turning without a command")
    await until_async("the fault", lambda: faults)
    assert faults == [("abnormal_behaviour", "turning without a command")]
    await stays_async("ACTIVE", lambda: state_of(runner), lambda s: s is S.ACTIVE, window=0.05)
    assert "on_aborting" not in bot(runner).calls
    assert [s for s, _, _ in states] == [S.INACTIVE, S.ACTIVE]


async def test_hardware_failure_from_a_thread_while_inactive(runner: ComponentRunner) -> None:
    seen_on: list[int] = []
    runner.on_fault(lambda k, d: seen_on.append(threading.get_ident()))
    await runner.initialize()
    thread = threading.Thread(target=bot(runner).hardware_failure, args=("lidar gone",))
    thread.start()
    thread.join()
    await until_async("ERROR", lambda: state_of(runner), lambda s: s is S.ERROR)
    assert seen_on == [threading.get_ident()]  # handed over to the loop's thread
    assert runner.last_error == "hardware_failure: lidar gone"
    assert "on_aborting" not in bot(runner).calls  # it was not ACTIVE


async def test_many_threads_reporting_at_once_lose_nothing(runner: ComponentRunner) -> None:
    faults, _ = record(runner)
    await runner.initialize()
    await runner.activate()
    threads = [
        threading.Thread(target=bot(runner).abnormal_behaviour, args=(f"t{i}",)) for i in range(8)
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    await until_async("eight faults", lambda: faults, lambda f: len(f) == 8)
    assert sorted(d for _, d in faults) == [f"t{i}" for i in range(8)]


async def test_fault_during_on_initialize_errors_after_it() -> None:
    comp = Robot("bot")
    comp.fault_on_initialize = ("hardware_failure", "no camera at /dev/video0")
    r = ComponentRunner(comp)
    _faults, states = record(r)
    await r.initialize()  # on_initialize itself returned: the transition completes
    await until_async("ERROR", lambda: state_of(r), lambda s: s is S.ERROR)
    assert [s for s, _, _ in states] == [S.INACTIVE, S.ERROR]
    await r.finalize()


async def test_a_transition_asked_right_after_the_fault_sees_error_first(
    runner: ComponentRunner,
) -> None:
    await runner.initialize()
    await runner.activate()
    bot(runner).emergency_stop("e-stop button")  # on the loop, outside any callback
    with pytest.raises(Exception, match="cannot deactivate: component is ERROR"):
        await runner.deactivate()
    assert bot(runner).calls.count("on_aborting") == 1


async def test_finalize_right_after_the_fault_still_aborts_first(runner: ComponentRunner) -> None:
    await runner.initialize()
    await runner.activate()
    bot(runner).emergency_stop("e-stop button")
    await runner.finalize()
    calls = [c for c in bot(runner).calls if c != "on_execute"]
    assert calls[-2:] == ["on_aborting", "on_finalize"]


async def test_a_fault_in_error_is_reported_but_changes_nothing(runner: ComponentRunner) -> None:
    faults, states = record(runner)
    await runner.initialize()
    await runner.activate()
    bot(runner).emergency_stop("first")
    await until_async("ERROR", lambda: state_of(runner), lambda s: s is S.ERROR)
    bot(runner).hardware_failure("second")
    await until_async("the second fault", lambda: faults, lambda f: len(f) == 2)
    await stays_async("one move to ERROR", lambda: states, lambda s: len(s) == 3, window=0.02)
    assert [k for k, _ in faults] == ["emergency_stop", "hardware_failure"]
    assert [s for s, _, _ in states].count(S.ERROR) == 1
    assert runner.last_error == "emergency_stop: first"
    assert bot(runner).calls.count("on_aborting") == 1


# -- end to end: real hosts under the agent's InstanceManager --------------------------------


class Seen:
    """What the manager's hooks were called with, and when (loop time)."""

    def __init__(self) -> None:
        self.faults: list[tuple[str, str, str]] = []
        self.problems: list[tuple[str, str]] = []

    def fault(self, name: str, kind: str, detail: str) -> None:
        self.faults.append((name, kind, detail))

    def problem(self, name: str, cause: str, detail: str = "") -> None:
        self.problems.append((name, cause))


def fixture_spec(name: str, cls: str, **params: Any) -> InstanceSpec:
    doc = {"name": name, "target": f"tests.components_fixture:{cls}", "params": params}
    return InstanceSpec.from_json(doc)


@pytest.fixture
async def managed(tmp_path: Path) -> AsyncIterator[tuple[InstanceManager, Seen]]:
    seen = Seen()
    manager = InstanceManager(
        tmp_path,
        replace(supervisor_fast(), max_faults=3),
        interval=0.1,
        on_fault=seen.fault,
        on_instance_problem=seen.problem,
    )
    await manager.start()
    try:
        yield manager, seen
    finally:
        await asyncio.wait_for(manager.stop(), 10)


def state(manager: InstanceManager, name: str) -> str:
    return str(manager.status_of(name)["state"])


async def test_emergency_stop_reaches_the_managers_hook_and_errors_without_a_problem(
    managed: tuple[InstanceManager, Seen],
) -> None:
    manager, seen = managed
    manager.set_desired([fixture_spec("Stop1", "Reporter", kinds="emergency_stop")])
    await until_async("the fault", lambda: seen.faults)
    assert seen.faults == [("Stop1", "emergency_stop", "#0")]
    await until_async("ERROR", lambda: state(manager, "Stop1"), lambda s: s == "ERROR")
    status = manager.status_of("Stop1")
    assert status["last_error"] == "emergency_stop: #0"
    assert [(f["kind"], f["detail"]) for f in status["faults"]] == [("emergency_stop", "#0")]
    assert status["faults"][0]["ts"] <= status["faults"][0]["received"] + 1
    # the fault's hook already told; no component_error on top (the manager checks every 0.1 s)
    await stays_async("no instance problem", lambda: seen.problems, lambda p: p == [], window=0.2)


async def test_faults_from_a_thread_in_order_and_the_status_keeps_the_last_few(
    managed: tuple[InstanceManager, Seen],
) -> None:
    manager, seen = managed
    kinds = ",".join(["abnormal_behaviour"] * 5)
    manager.set_desired([fixture_spec("Odd", "Reporter", kinds=kinds, thread=True)])
    await until_async("five faults", lambda: seen.faults, lambda f: len(f) == 5)
    assert [d for _, _, d in seen.faults] == ["#0", "#1", "#2", "#3", "#4"]
    assert [f["detail"] for f in manager.status_of("Odd")["faults"]] == ["#2", "#3", "#4"]
    assert state(manager, "Odd") == "ACTIVE"  # abnormal_behaviour only reports


async def test_a_failing_callback_is_a_component_error_and_a_kill_a_crash(
    managed: tuple[InstanceManager, Seen],
) -> None:
    manager, seen = managed
    manager.set_desired([fixture_spec("Crash", "Crasher", after=3), fixture_spec("Pub", "Counter")])
    await until_async(
        "component_error", lambda: seen.problems, lambda p: ("Crash", "component_error") in p
    )
    assert state(manager, "Crash") == "ERROR"
    await until_async("Pub ACTIVE", lambda: state(manager, "Pub"), lambda s: s == "ACTIVE")
    pid = manager.status_of("Pub")["pid"]
    os.kill(pid, signal.SIGKILL)
    await until_async("crashed", lambda: seen.problems, lambda p: ("Pub", "crashed") in p)
    assert seen.problems.count(("Crash", "component_error")) == 1
    assert seen.faults == []
    await until_async(
        "Pub restarted", lambda: manager.status_of("Pub")["pid"], lambda p: p not in (None, pid)
    )
    await manager.stop()
    assert seen.problems[-1] == ("Pub", "crashed")  # stopping on purpose is no problem


def test_a_fault_before_any_loop_runs_is_applied_when_the_runner_starts() -> None:
    r = ComponentRunner(Robot("early"))  # made outside a loop, as a script might
    faults, states = record(r)
    bot(r).hardware_failure("no device")
    assert faults == [("hardware_failure", "no device")]

    async def start() -> None:
        await r.initialize()  # settles the pending move first: CREATED -> ERROR
        await r.finalize()

    with pytest.raises(Exception, match="cannot initialize: component is ERROR"):
        asyncio.run(start())
    assert [s for s, _, _ in states] == [S.ERROR]
