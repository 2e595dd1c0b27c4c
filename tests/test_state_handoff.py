"""State handoff: on_snapshot/on_restore in the runner (the rules of sdrpeer.sdk.handoff), the
paper's components continuing after a migration, the control channel's parts, and end to end
through real hosts and the agent's Supervisor (size limit, malformed states)."""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import signal
from collections.abc import AsyncIterator, Callable
from dataclasses import replace
from pathlib import Path
from typing import Any

import msgpack
import pytest

from components.position_estimation import Estimator, PositionEstimation
from components.red_controller import Odometry, REDController
from sdrpeer.control.messages import Activate, Conn, Connect, Deactivate, Repoint
from sdrpeer.control.parts import PART_SIZE, PartAssembler, parts
from sdrpeer.errors import CommandError, PartError, StateError
from sdrpeer.runtime.config import SupervisorConfig
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.runtime.supervisor import Supervisor
from sdrpeer.sdk import (
    CallbackError,
    Component,
    ComponentRunner,
    InPort,
    LifecycleError,
    LifecycleState,
    OnInput,
    OutPort,
)
from tests.hostctl import HostPool
from tests.wait import stays_async, until_answer, until_async

S = LifecycleState
PE = "components.position_estimation:PositionEstimation"


class Plain(Component):
    """No on_snapshot, no on_restore."""

    execution = OnInput("inp")
    inp = InPort("anything")


class Counted(Component):
    """An async on_snapshot; an on_restore that checks before it changes anything."""

    out = OutPort("n")

    def on_initialize(self) -> None:
        self.n = 0

    async def on_snapshot(self) -> Any:
        await asyncio.sleep(0)
        return {"n": self.n}

    def on_restore(self, state: Any) -> None:
        if not isinstance(state, dict) or type(state.get("n")) is not int:
            raise ValueError(f"expected {{'n': int}}, got {state!r}")
        self.n = state["n"]


# -- the runner's rules ------------------------------------------------------------------------


async def test_snapshot_and_restore_by_state() -> None:
    r = ComponentRunner(Counted("c"))
    with pytest.raises(LifecycleError, match="cannot snapshot: component is CREATED"):
        await r.snapshot()
    await r.initialize()
    assert await r.snapshot() == {"n": 0}
    await r.restore({"n": 5})
    await r.activate()
    assert await r.snapshot() == {"n": 5}
    await r.restore({"n": 6})  # while ACTIVE too
    assert await r.snapshot() == {"n": 6}
    r.component.emergency_stop("test")
    await until_async("ERROR", lambda: r.state, lambda state: state is S.ERROR)
    assert await r.snapshot() == {"n": 6}  # in ERROR: a successor may still want it
    with pytest.raises(
        LifecycleError, match=r"cannot restore: component is ERROR \(reset it first"
    ):
        await r.restore({"n": 7})
    await r.finalize()
    with pytest.raises(LifecycleError, match="cannot snapshot: component is FINALIZED"):
        await r.snapshot()


async def test_a_refused_restore_changes_neither_state_nor_lifecycle() -> None:
    r = ComponentRunner(Counted("c"))
    await r.initialize()
    await r.activate()
    with pytest.raises(CallbackError, match=r"on_restore failed: ValueError: expected \{'n': int"):
        await r.restore({"n": "seven"})
    assert r.state is S.ACTIVE
    assert await r.snapshot() == {"n": 0}
    await r.finalize()


async def test_without_the_callbacks_the_state_is_none() -> None:
    r = ComponentRunner(Plain("p"))
    await r.initialize()
    assert await r.snapshot() is None
    await r.restore(None)
    with pytest.raises(CallbackError, match="Plain has no on_restore: it takes no state"):
        await r.restore({"x": 1})
    await r.finalize()


# -- the paper's components continue where the old instance stopped -----------------------------


def odometry_path(n: int) -> list[dict[str, float]]:
    """A turning path (so the heading-bias correction matters) as odometry samples."""
    out, odo = [], Odometry()
    for _ in range(n):
        d, dtheta = 0.05, 0.08
        mid = odo.theta + dtheta / 2
        odo = Odometry(odo.x + d * math.cos(mid), odo.y + d * math.sin(mid), odo.theta + dtheta)
        out.append({"x": odo.x, "y": odo.y, "theta": odo.theta, "ts": 0.0})
    return out


def test_estimator_migrated_halfway_ends_where_one_estimator_would() -> None:
    path = [Odometry(s["x"], s["y"], s["theta"]) for s in odometry_path(40)]
    whole = Estimator(bias=0.3)
    for odo in path:
        whole.update(odo)
    first, second = Estimator(bias=0.3), Estimator(bias=0.3)
    for odo in path[:20]:
        first.update(odo)
    second.load(msgpack.unpackb(msgpack.packb(first.state())))  # through the wire format
    for odo in path[20:]:
        second.update(odo)
    assert second.pose == whole.pose
    fresh = Estimator(bias=0.3)
    for odo in path[20:]:
        fresh.update(odo)
    assert math.dist((fresh.pose.x, fresh.pose.y), (whole.pose.x, whole.pose.y)) > 0.05


@pytest.mark.parametrize(
    ("state", "error"),
    [
        ("pose", "expected a map with v=1"),
        ({"v": 2}, "expected a map with v=1"),
        ({"v": 1, "pose": [1, 2]}, "'pose': expected [x, y, theta]"),
        ({"v": 1, "pose": [1, 2, float("nan")]}, "'pose': expected [x, y, theta]"),
        ({"v": 1, "pose": [1, 2, 3], "prev": "x"}, "'prev': expected [x, y, theta]"),
        ({"v": 1, "pose": [1, 2, 3], "glitches": -1}, "'glitches': expected a count"),
    ],
)
def test_estimator_refuses_a_malformed_state_and_keeps_its_own(state: Any, error: str) -> None:
    est = Estimator()
    est.update(Odometry(1.0, 0.0, 0.0))
    before = est.state()
    with pytest.raises(ValueError, match=error.replace("[", r"\[")):
        est.load(state)
    assert est.state() == before


class Sink:
    def __init__(self) -> None:
        self.values: list[Any] = []

    def offer(self, value: Any) -> bool:
        self.values.append(value)
        return True


async def feed(
    pe: PositionEstimation, sink: Sink, samples: list[dict[str, float]], seq0: int
) -> None:
    for i, sample in enumerate(samples):
        n = len(sink.values)
        pe.odometry.deliver(sample, seq0 + i, "ctl")
        grew = lambda v: len(v) > n  # noqa: B023, E731 - awaited before the loop moves on
        await until_async(f"pose {seq0 + i}", lambda: sink.values, grew)


async def test_position_estimation_migrated_mid_path_continues_the_estimate() -> None:
    path = odometry_path(30)
    params = {"bias": 0.3, "area": "-9,-9,9,9"}
    whole, whole_out = PositionEstimation("whole", params), Sink()
    old, old_out = PositionEstimation("old", params), Sink()
    new, new_out = PositionEstimation("new", params), Sink()
    runners = []
    for comp, sink in ((whole, whole_out), (old, old_out), (new, new_out)):
        comp.outport("pose").attach(sink)
        runner = ComponentRunner(comp)
        await runner.initialize()
        runners.append(runner)
    r_whole, r_old, r_new = runners
    await r_whole.activate()
    await r_old.activate()
    await feed(whole, whole_out, path, 1)
    await feed(old, old_out, path[:15], 1)
    await r_old.deactivate()  # the old one stops; its successor is INACTIVE
    state = await r_old.snapshot()
    await r_new.restore(state)
    await r_new.activate()  # the restored estimate survives the activation
    assert await r_new.snapshot() == state
    await feed(new, new_out, path[15:], 16)
    last = new_out.values[-1]
    assert (last["x"], last["y"], last["theta"]) == pytest.approx(
        (whole_out.values[-1]["x"], whole_out.values[-1]["y"], whole_out.values[-1]["theta"])
    )
    for runner in runners:
        await runner.finalize()


async def test_red_controller_odometry_continues_after_a_restore() -> None:
    params = {"rate": 200.0, "speed": 0.5, "turn": 0.0, "drift": 0.0}
    old, new = REDController("old", params), REDController("new", params)
    sink = Sink()
    new.outport("odometry").attach(sink)
    r_old, r_new = ComponentRunner(old), ComponentRunner(new)
    await r_old.initialize()
    await r_new.initialize()
    assert await r_old.snapshot() is None  # never activated: nothing to hand over
    await r_old.activate()
    await until_async("the robot moving", lambda: old.odo.x, lambda x: x > 0.05)
    await r_old.deactivate()
    state = await r_old.snapshot()
    assert state == {"v": 1, "odometry": [old.odo.x, 0.0, 0.0], "stops": 0}
    await r_new.restore(state)
    await r_new.activate()
    await until_async("three odometry samples", lambda: sink.values, lambda v: len(v) >= 3)
    xs = [v["x"] for v in sink.values]
    assert xs[0] == state["odometry"][0]  # not the origin
    assert xs == sorted(xs)
    with pytest.raises(CallbackError, match="'odometry': expected"):
        await r_new.restore({"v": 1, "odometry": None})
    await r_new.deactivate()
    await r_new.activate()  # a later activation starts afresh again
    n = len(sink.values)
    await until_async("a new sample", lambda: sink.values, lambda v: len(v) > n)
    assert sink.values[n]["x"] == 0.0
    await r_old.finalize()
    await r_new.finalize()


# -- parts (the pure core) ----------------------------------------------------------------------


def test_parts_reassemble_and_bad_transfers_say_why() -> None:
    blob = os.urandom(2 * PART_SIZE + 5)
    msgs = parts(3, blob)
    assert [len(m.data) for m in msgs] == [PART_SIZE, PART_SIZE, 5]
    asm = PartAssembler()
    for m in msgs:
        asm.add(m.of, m.data, limit=len(blob))
    assert asm.take(3, len(blob)) == blob
    for m in msgs:
        asm.add(m.of, m.data, limit=len(blob) - 1)
    with pytest.raises(PartError, match=f"over the limit of {len(blob) - 1} bytes"):
        asm.take(3, len(blob))
    asm.add(4, b"abc", 10)
    asm.add(5, b"d", 10)  # a new transfer drops the unfinished one
    assert asm.dropped == 1
    with pytest.raises(PartError, match="got 0 bytes in parts, 'size' says 3"):
        asm.take(4, 3)
    assert asm.take(5, 1) == b"d"
    assert parts(1, b"") == []


# -- real hosts through the agent's Supervisor ---------------------------------------------------


def pe_spec(name: str) -> InstanceSpec:
    params = {"area": "-50,-50,50,50", "bias": 0.1, "max_step": 5.0}
    return InstanceSpec.from_json({"name": name, "target": PE, "params": params})


def fixture_spec(name: str, cls: str, **params: Any) -> InstanceSpec:
    doc = {"name": name, "target": f"tests.components_fixture:{cls}", "params": params}
    return InstanceSpec.from_json(doc)


@pytest.fixture
async def sups(tmp_path: Path) -> AsyncIterator[Callable[..., Supervisor]]:
    made: list[Supervisor] = []

    def make(spec: InstanceSpec, config: SupervisorConfig | None = None) -> Supervisor:
        sup = Supervisor(spec, tmp_path, config or supervisor_fast())
        made.append(sup)
        sup.start()
        return sup

    yield make
    for sup in made:
        pid = sup.pid
        try:
            await asyncio.wait_for(sup.stop(), 5.0)
        finally:
            if pid is not None:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)


async def ready(sup: Supervisor, state: str = "INACTIVE") -> None:
    await until_async(
        f"{sup.name} {state}",
        lambda: (sup.state, sup.last_error),
        lambda seen: seen[0] == state,
        within=15.0,
    )


async def test_a_running_position_estimation_migrates_with_its_pose(sups: Any) -> None:
    ctl = sups(
        InstanceSpec.from_json(
            {
                "name": "Ctl",
                "target": "components.red_controller:REDController",
                "params": {"rate": 100.0, "speed": 0.5, "turn": 0.4},
            }
        )
    )
    old, new = sups(pe_spec("PE1")), sups(pe_spec("PE2"))
    for sup in (ctl, old, new):
        await ready(sup)
    await old.command(Activate())
    to = old.data_address()
    assert to is not None
    await ctl.command(Connect(Conn("odo", "odometry", to, "odometry")))
    await ctl.command(Activate())
    await until_answer(
        "PE1's pose past x 0.1",
        old.snapshot,  # while it runs
        lambda snap: bool(snap and snap["pose"][0] > 0.1),
    )
    await old.command(Deactivate())
    state = await old.snapshot()
    await new.restore(state)
    assert await new.snapshot() == state  # the same pose, through two hosts
    # Shift the estimate 10 m so continuing is told apart from starting afresh (which would
    # anchor on the controller's raw odometry, near the origin).
    x, y, theta = state["pose"]
    await new.restore({**state, "pose": [x + 10.0, y, theta]})
    to = new.data_address()
    assert to is not None
    await ctl.command(Repoint("odo", to))
    await new.command(Activate())

    after = await until_answer(
        "PE2 past the handed-over sample", new.snapshot, lambda now: now["prev"] != state["prev"]
    )
    assert after["glitches"] == state["glitches"]  # no re-anchoring: it continued
    assert math.dist(after["pose"][:2], (x + 10.0, y)) < 1.0


async def test_a_big_state_travels_in_parts_and_an_oversized_one_is_refused(sups: Any) -> None:
    config = replace(supervisor_fast(), max_state=3 << 20)
    big = sups(fixture_spec("Big", "Hoarder", kb=2500), config)  # 2.5 MiB: ten parts
    huge = sups(fixture_spec("Huge", "Hoarder", kb=4096), config)  # 4 MiB: over the limit
    other = sups(fixture_spec("Other", "Hoarder", kb=1), config)
    for sup in (big, huge, other):
        await ready(sup)
    state = await big.snapshot()
    assert state["blob"] == bytes(range(256)) * 2500 * 4
    await other.restore(state)
    assert await other.snapshot() == state
    with pytest.raises(CommandError, match=r"state of \d+ bytes is over the limit of 3145728"):
        await huge.snapshot()
    with pytest.raises(StateError, match=r"restore: refused \(state of \d+ bytes is over the lim"):
        await other.restore({"blob": bytes(4 << 20)})
    with pytest.raises(StateError, match="msgpack cannot encode"):
        await other.restore({"blob": object()})
    assert huge.alive
    assert other.alive
    assert (await other.snapshot()) == state  # refusals changed nothing


async def test_a_malformed_state_is_refused_and_the_host_lives_on(sups: Any) -> None:
    pe = sups(pe_spec("PE"))
    await ready(pe)
    await pe.command(Activate())
    pid = pe.pid
    for bad in ({"v": 1, "pose": "here"}, [1, 2, 3]):
        with pytest.raises(CommandError, match="on_restore failed: ValueError"):
            await pe.restore(bad)
    await stays_async(
        "PE alive and ACTIVE",
        lambda: (pe.alive, pe.pid, pe.state),
        lambda seen: seen == (True, pid, "ACTIVE"),
        window=0.1,
    )
    assert (await pe.snapshot())["v"] == 1


def test_restore_commands_whose_parts_do_not_add_up_are_refused(hosts: HostPool) -> None:
    host, _ = hosts.ready("tests.components_fixture:Hoarder")
    no_parts = host.command("restore")
    assert no_parts["ok"] is False
    assert "no 'size'" in no_parts["error"]
    host.send({"t": "part", "of": 50, "data": b"abc"})
    short = host.command("restore", size=4)  # id 2: the parts were for 50
    assert "got 0 bytes in parts" in short["error"]
    host.send({"t": "part", "of": 3, "data": b"\xc1"})
    garbage = host.command("restore", size=1)
    assert "state is not one msgpack value" in garbage["error"]
    snap = host.command("snapshot", max=10)
    assert "over the limit of 10 bytes" in snap["error"]
    snap = host.command("snapshot")
    pieces = [m for m in host.seen if m["t"] == "part" and m["of"] == snap["id"]]
    blob = b"".join(p["data"] for p in pieces)
    assert snap["ok"] is True
    assert len(blob) == snap["size"]
    assert msgpack.unpackb(blob)["blob"] == bytes(range(256)) * 4
    assert host.proc.poll() is None
    assert host.command("exit")["ok"] is True
