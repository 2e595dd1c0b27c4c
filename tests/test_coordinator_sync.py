"""Plan sync. Against a robot whose API does not answer (restarting: gossip is back before the
API): the coordinator waits `DeployConfig.fetch_retry` before it asks that robot again, instead
of fetching in a tight loop (it did, hundreds of times a second, on every agent of a 10-robot
soak). And the old side of a heal: gossip of a newer plan's running copy stands its own copy
down at once. And a plan placing what this robot's launch policy refuses launches nothing."""

from __future__ import annotations

import asyncio
import itertools
from dataclasses import replace
from pathlib import Path

import pytest

from sdrpeer.deploy import peers
from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import ApiError
from sdrpeer.plan import Placement, Plan
from sdrpeer.record.robot import InstanceInfo, LinkSummary, Metrics, PlanInfo, RobotRecord
from sdrpeer.system.loader import parse_system
from sdrpeer.vocabulary import LifecycleState
from tests.test_shutdown import coordinator_with
from tests.virtual_time import run_virtual
from tests.wait import until_async


def test_a_failed_fetch_is_not_retried_at_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """On virtual loop time (tests/virtual_time.py): the fetch times are exact."""
    calls: list[float] = []

    async def refused(api: str, token: str) -> Plan:
        calls.append(asyncio.get_running_loop().time())
        raise ApiError(f"{api}/v1/plan: connection refused")

    monkeypatch.setattr(peers, "fetch_plan", refused)
    metrics = Metrics(5.0, 10**9, 10**9, 90.0, -45.0, (0.0, 0.0))
    offers = RobotRecord(
        metrics, LinkSummary(), "http://127.0.0.1:9", 0, (), plan=PlanInfo(3, 1, "d", "robot-2")
    )
    me = RobotRecord(metrics, LinkSummary(), "http://127.0.0.1:8", 0, ())
    state = ClusterState({"robot-1": me, "robot-2": offers}, ["robot-1", "robot-2"])
    retry = DeployConfig().fetch_retry

    async def scenario() -> None:
        c, manager = await coordinator_with(tmp_path, state)
        try:
            c.start()
            await asyncio.sleep(retry * 2.5)
        finally:
            await c.stop()
            await manager.stop()

    run_virtual(scenario())
    # one now, then one per fetch_retry, at the first tick (0.01 s) it is due
    assert calls == pytest.approx([0.0, retry, 2 * retry], abs=0.011)
    assert all(b - a >= retry for a, b in itertools.pairwise(calls))


async def test_the_old_side_of_a_heal_stands_down_before_it_has_the_newer_plan(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """robot-1 runs Cnt ACTIVE under plan (1, robot-1, 1). After a heal, gossip shows robot-2
    holding a newer plan and running Cnt ACTIVE as its active; robot-2's API does not answer
    (the fetch hangs). robot-1 stands its copy down anyway, and says why in an event."""

    async def hangs(api: str, token: str) -> Plan:
        await asyncio.Event().wait()
        raise AssertionError("unreachable")

    monkeypatch.setattr(peers, "fetch_plan", hangs)
    system = parse_system(
        "name: s\ncomponents:\n  - {name: Cnt, target: tests.components_fixture:Counter,"
        " params: {rate: 5}}\n",
        "s.yaml",
    )
    old = Plan(1, 1, system, (Placement("Cnt", "Cnt", "robot-1"),), allocator="robot-1")
    metrics = Metrics(5.0, 10**9, 10**9, 90.0, -45.0, (0.0, 0.0))
    me = RobotRecord(metrics, LinkSummary(), "http://127.0.0.1:8", 0, ())
    other = RobotRecord(metrics, LinkSummary(), "http://127.0.0.1:9", 0, ())
    state = ClusterState({"robot-1": me, "robot-2": other}, ["robot-1", "robot-2"])
    c, manager = await coordinator_with(tmp_path, state)

    def cnt_state() -> str | None:
        return next((s.get("state") for s in manager.status() if s["name"] == "Cnt"), None)

    try:
        c.start()
        assert c.accept(old, source="robot-1")
        await until_async("Cnt ACTIVE", cnt_state, lambda s: s == "ACTIVE", within=60, poll=0.02)
        running = InstanceInfo(
            "Cnt", "Cnt", LifecycleState.ACTIVE, "active", 1.0, 10**7, "tcp://127.0.0.1:7"
        )
        state.alive["robot-2"] = replace(
            other, instances=(running,), plan=PlanInfo(2, 1, "d", "robot-2")
        )
        c.wake()
        await until_async(
            "Cnt stood down", cnt_state, lambda s: s == "INACTIVE", within=30, poll=0.02
        )
        assert c.store.plan is old  # not fetched: gossip alone made it yield
        (event,) = [e for e in c.events.since(0) if e["kind"] == "plan.superseded"]
        assert event["detail"] == {"instance": "Cnt", "newer": ["robot-2"]}
        state.alive["robot-2"] = replace(other, plan=PlanInfo(2, 1, "d", "robot-2"))
        c.wake()  # the newer copy is gone (and its plan never came): robot-1's runs again
        await until_async(
            "Cnt ACTIVE again", cnt_state, lambda s: s == "ACTIVE", within=30, poll=0.02
        )
    finally:
        await c.stop()
        await manager.stop()


async def test_a_plan_placing_what_the_launch_policy_refuses_launches_nothing(
    tmp_path: Path,
) -> None:
    """A plan (from an allocator that did not know this robot's policy yet) places an exec
    component here: the coordinator keeps it out of the desired set and says why, once."""
    system = parse_system(
        "name: s\ncomponents:\n  - {name: Sh, launcher: exec, target: [/bin/sh, -c, 'exit 0']}\n"
        "  - {name: Cnt, target: tests.components_fixture:Counter, params: {rate: 5}}\n",
        "s.yaml",
    )
    placements = (Placement("Sh", "Sh", "robot-1"), Placement("Cnt", "Cnt", "robot-1"))
    plan = Plan(1, 1, system, placements, allocator="robot-2")
    c, manager = await coordinator_with(tmp_path)
    try:
        c.start()
        assert c.accept(plan, source="robot-2")
        for _ in range(5):  # more steps: the refusal is said once
            c.step()
        assert sorted(manager.desired()) == ["Cnt"]
        (event,) = [e for e in c.events.since(0) if e["kind"] == "launch.refused"]
        assert event["detail"]["instance"] == "Sh"
        assert "launcher 'exec' is off on this robot" in event["detail"]["reason"]
    finally:
        await c.stop()
        await manager.stop()
