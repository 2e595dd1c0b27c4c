"""Plan sync against a robot whose API does not answer (restarting: gossip is back before the
API): the coordinator waits FETCH_RETRY before it asks that robot again, instead of fetching in
a tight loop (it did, hundreds of times a second, on every agent of a 10-robot soak)."""

from __future__ import annotations

import asyncio
import itertools
from pathlib import Path

import pytest

from sdrpeer.deploy import peers
from sdrpeer.deploy.coordinator import FETCH_RETRY
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import ApiError
from sdrpeer.plan import Plan
from sdrpeer.record import LinkSummary, Metrics, PlanInfo, RobotRecord
from tests.test_shutdown import coordinator_with


async def test_a_failed_fetch_is_not_retried_at_once(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
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
    c, manager = await coordinator_with(tmp_path, state)
    try:
        c.start()
        loop = asyncio.get_running_loop()
        async with asyncio.timeout(30):
            while not calls or loop.time() - calls[0] < FETCH_RETRY * 2.5:  # noqa: ASYNC110
                await asyncio.sleep(0.01)
        assert 2 <= len(calls) <= 4, len(calls)  # one now, then one per FETCH_RETRY
        gaps = [b - a for a, b in itertools.pairwise(calls)]
        assert min(gaps) >= FETCH_RETRY
    finally:
        await c.stop()
        await manager.stop()
