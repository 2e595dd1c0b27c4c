"""No shutdown can hang (issue 14): a cancel that arrives just as a loop's wake event is set is
not swallowed (Python 3.11's `asyncio.wait_for` returned normally then, and the coordinator's
loop ran on for ever); a graceful stop that overruns its deadline kills the component hosts and
exits anyway, saying what it was waiting for."""

from __future__ import annotations

import asyncio
import os
import signal
import time
from pathlib import Path

import psutil
import pytest

from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.coordinator import Coordinator
from sdrpeer.deploy.view import ClusterState
from sdrpeer.eventlog import EventLog
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.manager import InstanceManager
from tests.realnet import RealCluster
from tests.test_recovery_e2e import deploy


async def coordinator_with(
    tmp_path: Path, state: ClusterState | None = None
) -> tuple[Coordinator, InstanceManager]:
    """robot-1's coordinator on fast ticks, with a started instance manager, seeing `state`
    (default: no robot); the caller stops both."""
    manager = InstanceManager(tmp_path / "m", supervisor_fast(), interval=0.05)
    await manager.start()
    seen = state if state is not None else ClusterState({})
    coordinator = Coordinator(
        "robot-1",
        tmp_path,
        manager,
        lambda: seen,
        token="t" * 32,
        events=EventLog(),
        on_change=lambda: None,
        config=DeployConfig(tick=0.01, idle_tick=0.01),
    )
    return coordinator, manager


@pytest.mark.parametrize("yields", [0, 1, 2, 3, 4])
async def test_a_stop_right_after_a_wake_is_not_swallowed(tmp_path: Path, yields: int) -> None:
    """The exact race: the wake event is set (a peer's leave record during a fleet-wide stop),
    then the loop is cancelled a few loop iterations later. Every interleaving must stop."""
    coordinator, manager = await coordinator_with(tmp_path)
    try:
        coordinator.start()
        for _ in range(20):  # many rounds: the loop is at a different point in each
            await asyncio.sleep(0.003)
            coordinator.wake()
            for _ in range(yields):
                await asyncio.sleep(0)
            task = coordinator._task
            assert task is not None
            task.cancel()
            done, _ = await asyncio.wait({task}, timeout=10)  # a swallowed cancel: it runs on
            assert task in done, "the loop swallowed its cancel"
            assert task.cancelled()
            coordinator.start()
    finally:
        async with asyncio.timeout(10):
            await coordinator.stop()
            await manager.stop()


HANGS_ON_FINALIZE = """\
name: stuck
components:
  - name: Stuck
    target: tests.components_fixture:Stubborn
"""


@pytest.mark.realnet
def test_an_agent_whose_host_will_not_stop_exits_within_its_deadline(tmp_path: Path) -> None:
    """A component that ignores the exit request (its on_finalize never returns) and SIGTERM:
    SIGTERM to the agent still ends it within the stop deadline (2.5 s, plus the interpreter's
    exit); the log says what it waited for, and no host outlives it. The `lan` preset: its
    supervisor would wait 5 s for the exit, then 3 s for SIGTERM, before its SIGKILL (`fast_test`
    kills the host after 2 s, within the deadline)."""
    cluster = RealCluster(tmp_path / "net", preset="lan")
    try:
        agent = cluster.start_many(1)[0]
        path = tmp_path / "stuck.yaml"
        path.write_text(HANGS_ON_FINALIZE)
        deploy(cluster, agent, path)  # waits until it is ACTIVE
        instances = {i["name"]: i for i in agent.get("/v1/instances")}
        host = psutil.Process(int(instances["Stuck"]["pid"]))
        began = time.monotonic()
        os.kill(agent.pid, signal.SIGTERM)
        rc = agent.proc.wait(timeout=10)
        took = time.monotonic() - began
        assert rc == 1, "an overdue stop exits with 1"
        assert took < 20.0, f"{took:.1f} s"  # 2.5 s deadline, then exit 1 (below); generous on load
        log = agent.log.read_text()
        assert "stop still waiting for the component hosts" in log, log[-2000:]
        host_gone = not host.is_running() or host.status() == psutil.STATUS_ZOMBIE
        assert host_gone, "the host outlived its agent"
    finally:
        cluster.close()
