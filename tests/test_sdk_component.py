"""Component and ComponentRunner: lifecycle, execution contexts, errors, params, faults."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator
from typing import Any

import pytest

from sdrpeer.sdk import (
    CallbackError,
    Component,
    ComponentRunner,
    InPort,
    LifecycleError,
    LifecycleState,
    OnInput,
    OutPort,
    Param,
    ParamError,
    Periodic,
)
from sdrpeer.sdk.errors import ComponentError, PortError
from tests.virtual_time import run_virtual
from tests.wait import stays_async, until_async

S = LifecycleState


class Recorder(Component):
    """Records every callback; `fail` names callbacks that should raise."""

    execution = Periodic(hz=200.0)
    gain = Param(float, 1.0, on_change="_gain_changed")
    label = Param(str, "x")

    def __init__(self, name: str | None = None, **kw: Any) -> None:
        super().__init__(name, **kw)
        self.calls: list[str] = []
        self.fail: set[str] = set()
        self.changes: list[dict[str, Any]] = []

    def _hit(self, name: str) -> None:
        self.calls.append(name)
        if name in self.fail:
            raise RuntimeError(f"{name} broke")

    def on_initialize(self) -> None:
        self._hit("on_initialize")

    def on_activated(self) -> None:
        self._hit("on_activated")

    def on_execute(self) -> None:
        self._hit("on_execute")

    def on_deactivated(self) -> None:
        self._hit("on_deactivated")

    def on_aborting(self) -> None:
        self._hit("on_aborting")

    def on_error(self) -> None:
        self._hit("on_error")

    def on_reset(self) -> None:
        self._hit("on_reset")

    def on_finalize(self) -> None:
        self._hit("on_finalize")

    def on_params_changed(self, changed: dict[str, Any]) -> None:
        self.changes.append(changed)
        self._hit("on_params_changed")

    def _gain_changed(self, value: float) -> None:
        self._hit(f"gain={value}")


@pytest.fixture
async def runner() -> AsyncIterator[ComponentRunner]:
    r = ComponentRunner(Recorder("rec1"))
    yield r
    if r.state is not S.FINALIZED:
        await r.finalize()


def rec(r: ComponentRunner) -> Recorder:
    assert isinstance(r.component, Recorder)
    return r.component


def state_of(r: ComponentRunner) -> LifecycleState:
    """The runner's state (a call, so mypy does not narrow it across awaits)."""
    return r.state


# -- lifecycle -----------------------------------------------------------------------------


async def test_full_lifecycle_calls_callbacks_and_reports_each_state(
    runner: ComponentRunner,
) -> None:
    seen: list[tuple[LifecycleState, str | None]] = []
    runner.on_state(lambda s, e: seen.append((s, e)))
    assert runner.state is S.CREATED
    await runner.initialize()
    await runner.activate()
    await until_async(
        "two executions", lambda: rec(runner).calls.count("on_execute"), lambda n: n >= 2
    )
    await runner.deactivate()
    await runner.finalize()
    calls = [c for c in rec(runner).calls if c != "on_execute"]
    assert calls == ["on_initialize", "on_activated", "on_deactivated", "on_finalize"]
    assert seen == [(S.INACTIVE, None), (S.ACTIVE, None), (S.INACTIVE, None), (S.FINALIZED, None)]
    assert runner.executions == rec(runner).calls.count("on_execute")


@pytest.mark.parametrize(
    ("steps", "illegal", "message"),
    [
        ([], "activate", "cannot activate: component is CREATED"),
        (["initialize"], "initialize", "cannot initialize: component is INACTIVE"),
        (["initialize"], "deactivate", "cannot deactivate: component is INACTIVE"),
        (["initialize"], "reset", "cannot reset: component is INACTIVE"),
        (["initialize", "activate"], "activate", "cannot activate: component is ACTIVE"),
        (["initialize", "finalize"], "activate", "cannot activate: component is FINALIZED"),
        (["initialize", "finalize"], "finalize", "cannot finalize: component is FINALIZED"),
    ],
)
async def test_illegal_transitions_raise_and_run_no_callback(
    runner: ComponentRunner, steps: list[str], illegal: str, message: str
) -> None:
    for step in steps:
        await getattr(runner, step)()
    before = list(rec(runner).calls)
    state = runner.state
    with pytest.raises(LifecycleError, match=message):
        await getattr(runner, illegal)()
    assert runner.state is state
    assert [c for c in rec(runner).calls if c != "on_execute"] == [
        c for c in before if c != "on_execute"
    ]


async def test_finalize_from_active_deactivates_first(runner: ComponentRunner) -> None:
    await runner.initialize()
    await runner.activate()
    await runner.finalize()
    assert runner.state is S.FINALIZED
    assert rec(runner).calls[-2:] == ["on_deactivated", "on_finalize"]


# -- errors --------------------------------------------------------------------------------


async def test_exception_in_on_execute_is_reported_in_the_same_loop_iteration(
    runner: ComponentRunner,
) -> None:
    loop = asyncio.get_running_loop()
    events: list[str] = []
    comp = rec(runner)

    def explode() -> None:
        # Anything scheduled now runs in the *next* loop iteration: the report must come first.
        loop.call_soon(events.append, "next iteration")
        raise ValueError("sensor unplugged")

    comp.on_execute = explode  # type: ignore[method-assign]
    runner.on_state(lambda s, e: events.append(f"{s}:{e}"))
    await runner.initialize()
    await runner.activate()
    await until_async("the next iteration", lambda: events, lambda e: "next iteration" in e)
    assert events[2:4] == [
        "ERROR:on_execute: ValueError: sensor unplugged",
        "next iteration",
    ]
    assert runner.state is S.ERROR
    assert runner.last_error == "on_execute: ValueError: sensor unplugged"
    assert comp.last_error == runner.last_error


async def test_error_calls_on_aborting_once_then_on_error_per_period_and_reset_recovers(
    runner: ComponentRunner,
) -> None:
    comp = rec(runner)
    comp.fail.add("on_execute")
    await runner.initialize()
    await runner.activate()
    await until_async("three on_error", lambda: comp.calls, lambda c: c.count("on_error") >= 3)
    assert runner.state is S.ERROR
    assert comp.calls.count("on_aborting") == 1
    assert comp.calls.count("on_execute") == 1  # never called again while in ERROR
    first_error = comp.calls.index("on_error")
    assert comp.calls.index("on_aborting") < first_error
    with pytest.raises(LifecycleError, match=r"cannot activate: component is ERROR \(reset it"):
        await runner.activate()
    comp.fail.clear()
    await runner.reset()
    assert state_of(runner) is S.INACTIVE
    assert comp.calls[-1] == "on_reset"
    await runner.activate()
    n = comp.calls.count("on_execute")
    await until_async(
        "three more executions", lambda: comp.calls.count("on_execute"), lambda k: k > n + 2
    )
    assert state_of(runner) is S.ACTIVE


async def test_failing_on_activated_goes_inactive_to_error_without_aborting(
    runner: ComponentRunner,
) -> None:
    rec(runner).fail.add("on_activated")
    await runner.initialize()
    with pytest.raises(CallbackError, match="on_activated failed: on_activated: RuntimeError"):
        await runner.activate()
    assert runner.state is S.ERROR
    assert "on_aborting" not in rec(runner).calls


async def test_failing_on_initialize_reports_error_and_reset_initializes_again() -> None:
    comp = Recorder()
    comp.fail.add("on_initialize")
    runner = ComponentRunner(comp)
    seen: list[tuple[LifecycleState, str | None]] = []
    runner.on_state(lambda s, e: seen.append((s, e)))
    with pytest.raises(CallbackError):
        await runner.initialize()
    assert seen == [(S.ERROR, "on_initialize: RuntimeError: on_initialize broke")]
    comp.fail.clear()
    await runner.reset()
    assert comp.calls[-2:] == ["on_reset", "on_initialize"]
    assert runner.state is S.INACTIVE
    await runner.finalize()


async def test_failing_reset_stays_in_error(runner: ComponentRunner) -> None:
    comp = rec(runner)
    comp.fail.update({"on_activated", "on_reset"})
    await runner.initialize()
    with pytest.raises(CallbackError):
        await runner.activate()
    with pytest.raises(CallbackError, match="on_reset"):
        await runner.reset()
    assert runner.state is S.ERROR


async def test_failing_on_finalize_still_finalizes_and_reports_why(
    runner: ComponentRunner,
) -> None:
    seen: list[tuple[LifecycleState, str | None]] = []
    runner.on_state(lambda s, e: seen.append((s, e)))
    rec(runner).fail.add("on_finalize")
    await runner.initialize()
    await runner.finalize()
    assert seen[-1] == (S.FINALIZED, "on_finalize: RuntimeError: on_finalize broke")


async def test_a_failing_state_hook_does_not_stop_the_others(runner: ComponentRunner) -> None:
    seen: list[LifecycleState] = []

    def bad(_s: LifecycleState, _e: str | None) -> None:
        raise RuntimeError("hook bug")

    runner.on_state(bad)
    runner.on_state(lambda s, _e: seen.append(s))
    await runner.initialize()
    assert seen == [S.INACTIVE]


# -- execution contexts --------------------------------------------------------------------


class Ticker(Component):
    execution = Periodic(hz=20.0)

    def __init__(self) -> None:
        super().__init__()
        self.ticks = 0

    def on_execute(self) -> None:
        self.ticks += 1


def test_periodic_runs_at_its_rate_and_only_while_active() -> None:
    """On virtual loop time (tests/virtual_time.py) the count is exact, on any machine."""

    async def scenario() -> None:
        comp = Ticker()
        runner = ComponentRunner(comp)
        await runner.initialize()
        await asyncio.sleep(0.1)
        assert comp.ticks == 0  # INACTIVE: nothing runs
        await runner.activate()
        await asyncio.sleep(0.49)
        await runner.deactivate()
        assert comp.ticks == 10  # 20 Hz: at 0, 0.05, ..., 0.45 s
        await asyncio.sleep(1.0)
        assert comp.ticks == 10
        await runner.finalize()

    run_virtual(scenario())


class RateFromParam(Ticker):
    execution = Periodic(param="rate")
    rate = Param(float, 0.0, min=0.0)


def test_periodic_rate_from_a_param_changes_live() -> None:
    async def scenario() -> None:
        comp = RateFromParam()
        runner = ComponentRunner(comp)
        await runner.initialize()
        await runner.activate()
        await asyncio.sleep(1.0)
        assert comp.ticks == 0  # rate 0: paused
        assert await runner.set_params({"rate": "50"}) == {"rate": 50.0}
        await asyncio.sleep(0.299)
        assert comp.ticks == 15  # 50 Hz for 0.3 s: at 0, 0.02, ..., 0.28 s
        assert await runner.set_params({"rate": 10}) == {"rate": 10.0}
        await asyncio.sleep(0.5)
        assert comp.ticks == 20  # the next one 0.1 s after the last, then every 0.1 s
        await runner.set_params({"rate": 0})
        after = comp.ticks
        await asyncio.sleep(5.0)
        assert comp.ticks == after
        await runner.finalize()

    run_virtual(scenario())


class Echo(Component):
    execution = OnInput("inp")
    inp = InPort(policy={"buffer": 16})
    out = OutPort()

    def on_execute(self) -> None:
        self.out.write(self.inp.get_nowait() * 2)


class ListSink:
    def __init__(self) -> None:
        self.got: list[Any] = []

    def offer(self, value: Any) -> bool:
        self.got.append(value)
        return True


async def test_on_input_runs_once_per_frame_and_only_while_active() -> None:
    comp = Echo()
    sink = ListSink()
    comp.out.attach(sink)
    runner = ComponentRunner(comp)
    await runner.initialize()
    comp.inp.deliver(100, 1, "c")  # INACTIVE: queued, no execution
    await stays_async(
        "no output while INACTIVE", lambda: sink.got, lambda got: got == [], window=0.02
    )
    comp.inp.get_nowait()
    await runner.activate()
    comp.inp.deliver(1, 2, "c")
    await until_async("one output", lambda: sink.got, lambda got: len(got) == 1)
    for seq in range(3, 6):  # a burst: one execution per frame
        comp.inp.deliver(seq, seq, "c")
    await until_async("four outputs", lambda: sink.got, lambda got: len(got) == 4)
    await stays_async(
        "one output per frame", lambda: sink.got, lambda got: got == [2, 6, 8, 10], window=0.02
    )
    assert runner.executions == 4
    await runner.finalize()


class AsyncComp(Component):
    execution = OnInput("inp")
    inp = InPort()
    scale = Param(int, 1)

    def __init__(self) -> None:
        super().__init__()
        self.log_: list[Any] = []

    async def on_initialize(self) -> None:
        await asyncio.sleep(0)
        self.log_.append("init")

    async def on_activated(self) -> None:
        await asyncio.sleep(0)
        self.log_.append("activated")

    async def on_execute(self) -> None:
        await asyncio.sleep(0)
        value = self.inp.read()
        if value == "boom":
            raise KeyError("boom")
        self.log_.append(value * self.scale)

    async def on_aborting(self) -> None:
        await asyncio.sleep(0)
        self.log_.append("aborting")

    async def on_params_changed(self, changed: dict[str, Any]) -> None:
        await asyncio.sleep(0)
        self.log_.append(changed)


async def test_async_callbacks_work() -> None:
    comp = AsyncComp()
    runner = ComponentRunner(comp)
    states: list[LifecycleState] = []
    runner.on_state(lambda s, _e: states.append(s))
    await runner.initialize()
    await runner.activate()
    comp.inp.deliver(3, 1, "c")
    await until_async("3 executed", lambda: comp.log_, lambda log: 3 in log)
    await runner.set_params({"scale": "10"})
    comp.inp.deliver(4, 2, "c")
    await until_async("4 scaled by 10", lambda: comp.log_, lambda log: 40 in log)
    comp.inp.deliver("boom", 3, "c")
    await until_async("on_aborting", lambda: comp.log_, lambda log: "aborting" in log)
    assert comp.log_ == ["init", "activated", 3, {"scale": 10}, 40, "aborting"]
    assert states == [S.INACTIVE, S.ACTIVE, S.ERROR]
    assert runner.last_error == "on_execute: KeyError: 'boom'"
    await runner.finalize()


# -- params through the runner -------------------------------------------------------------


async def test_set_params_is_all_or_nothing_and_calls_hooks(runner: ComponentRunner) -> None:
    comp = rec(runner)
    assert await runner.set_params({"gain": "2"}) == {"gain": 2.0}  # CREATED: no callbacks
    assert comp.calls == []
    await runner.initialize()
    with pytest.raises(ParamError, match="param 'gain': expected float"):
        await runner.set_params({"label": "y", "gain": "lots"})
    assert comp.label == "x"  # nothing applied
    with pytest.raises(ParamError, match="param 'nope': unknown param"):
        await runner.set_params({"label": "y", "nope": 0})
    assert comp.label == "x"
    assert comp.gain == 2.0
    assert comp.calls == ["on_initialize"]  # no params callback ran


async def test_set_params_changes_only_what_differs(runner: ComponentRunner) -> None:
    comp = rec(runner)
    await runner.initialize()
    assert await runner.set_params({"label": "x"}) == {}
    assert comp.changes == []
    assert await runner.set_params({"label": "y", "gain": "3"}) == {"label": "y", "gain": 3.0}
    assert comp.calls[-2:] == ["gain=3.0", "on_params_changed"]
    assert comp.changes == [{"label": "y", "gain": 3.0}]
    assert comp.param_values() == {"gain": 3.0, "label": "y"}


async def test_failing_params_callback_while_active_goes_to_error(
    runner: ComponentRunner,
) -> None:
    comp = rec(runner)
    await runner.initialize()
    await runner.activate()
    comp.fail.add("on_params_changed")
    with pytest.raises(CallbackError, match="on_params_changed"):
        await runner.set_params({"label": "z"})
    assert runner.state is S.ERROR
    assert comp.label == "z"
    await runner.finalize()
    with pytest.raises(LifecycleError, match="cannot set_params: component is FINALIZED"):
        await runner.set_params({"label": "w"})


# -- faults, logging, declarations ---------------------------------------------------------


async def test_report_fault_reaches_the_runner_hook(runner: ComponentRunner) -> None:
    faults: list[tuple[str, str]] = []
    runner.on_fault(lambda k, d: faults.append((k, d)))
    rec(runner).report_fault("hardware_failure", "motor 2 stalled")
    rec(runner).report_fault("emergency_stop")
    assert faults == [("hardware_failure", "motor 2 stalled"), ("emergency_stop", "")]
    with pytest.raises(ValueError, match="kind 'oops' not in"):
        rec(runner).report_fault("oops")


def test_logger_and_instance_name() -> None:
    comp = Recorder("CameraRTC2")
    assert comp.instance_name == "CameraRTC2"
    assert comp.log.name == "sdrpeer.component.CameraRTC2"
    assert Recorder().instance_name == "Recorder"


def test_unknown_ports_are_named_in_the_error() -> None:
    with pytest.raises(PortError, match=r"no in-port 'out' \(in: inp\)"):
        Echo().inport("out")
    with pytest.raises(PortError, match="no out-port 'x'"):
        Echo().outport("x")


def test_bad_execution_declarations_fail_at_class_creation() -> None:
    with pytest.raises(ComponentError, match=r"OnInput\('nope'\) names no InPort"):

        class _A(Component):
            execution = OnInput("nope")

    with pytest.raises(ComponentError, match=r"Periodic\(param='label'\) names no int/float"):

        class _B(Component):
            execution = Periodic(param="label")
            label = Param(str, "x")

    with pytest.raises(ValueError, match="exactly one"):
        Periodic()
    with pytest.raises(ValueError, match="positive"):
        Periodic(hz=0)


class Fragile(Component):
    execution = OnInput("inp")
    inp = InPort()

    def __init__(self) -> None:
        super().__init__()
        self.errors = 0

    def on_execute(self) -> None:
        raise RuntimeError(f"bad frame {self.inp.get_nowait()}")

    def on_error(self) -> None:
        self.errors += 1
        self.inp.get_nowait()


async def test_on_input_calls_on_error_per_frame_while_in_error() -> None:
    comp = Fragile()
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    comp.inp.deliver(1, 1, "c")
    await until_async("ERROR", lambda: state_of(runner), lambda s: s is S.ERROR)
    assert runner.last_error == "on_execute: RuntimeError: bad frame 1"
    comp.inp.deliver(2, 2, "c")
    comp.inp.deliver(3, 3, "c")
    await until_async("two on_error", lambda: comp.errors, lambda n: n == 2)
    await stays_async("one on_error per frame", lambda: comp.errors, lambda n: n == 2, window=0.02)
    await runner.finalize()


class Slow(Component):
    execution = Periodic(hz=1000.0)

    def __init__(self) -> None:
        super().__init__()
        self.inside = False
        self.overlapped = False
        self.release = asyncio.Event()

    async def on_execute(self) -> None:
        self.inside = True
        await self.release.wait()
        self.inside = False

    async def on_deactivated(self) -> None:
        self.overlapped = self.inside


async def test_deactivate_waits_for_a_running_async_on_execute() -> None:
    comp = Slow()
    runner = ComponentRunner(comp)
    await runner.initialize()
    await runner.activate()
    await until_async("on_execute running", lambda: comp.inside)
    stopping = asyncio.ensure_future(runner.deactivate())
    await stays_async(
        "deactivate waiting for on_execute",
        lambda: (stopping.done(), state_of(runner)),
        lambda seen: seen == (False, S.ACTIVE),
        window=0.02,
    )
    comp.release.set()
    await asyncio.wait_for(stopping, 1.0)
    assert not comp.overlapped
    assert state_of(runner) is S.INACTIVE
    await runner.finalize()
