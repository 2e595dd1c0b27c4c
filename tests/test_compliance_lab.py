"""Continuous compliance on real agents in network namespaces (root): a connection's own loss
bound, real packet loss (iptables `statistic`) on the receiver's robot, the violation reported
as an event and in the status, and the receiver re-placed where its link holds."""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.client import AgentClient, post_when_elected
from sdrpeer.errors import ApiError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.netlab import net
from sdrpeer.record.robot import state_to_wire
from sdrpeer.vocabulary import LifecycleState
from tests.realnet import NETNS_ONLY
from tests.wait import until

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))

from bench_compliance import system as bench_system

pytestmark = pytest.mark.realnet
WITHIN, POLL = 60.0, 0.1
NOT_YET = (ApiError,)
SUSTAIN = 2.0
ACTIVE = state_to_wire(LifecycleState.ACTIVE)
"""How `GET /v1/status` spells an active instance's state."""


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:
    running = start_lab(
        UpOptions(3, tmp_path / "lab", preset="lan", netns=True, timeout=30), say=lambda _: None
    )
    try:
        yield running
    finally:
        running.stop(grace=3)
        assert net.load(tmp_path / "lab") is None


def det(status: dict[str, Any]) -> tuple[str | None, str | None]:
    """Det's robot and state (None, None before robot-1 holds the plan)."""
    row = next((c for c in status["components"] if c["component"] == "Det"), None)
    return (None, None) if row is None else (row["robot"], row["state"])


def events(clients: dict[str, AgentClient], kind: str) -> list[dict[str, Any]]:
    out = []
    for c in clients.values():
        with contextlib.suppress(ApiError):
            out += [e for e in c.events(0, 5000) if e["kind"] == kind]
    return out


@NETNS_ONLY
def test_a_lossy_link_past_a_connections_bound_is_reported_and_the_receiver_moves(
    lab: RunningLab,
) -> None:
    clients = {r.name: AgentClient(str(r.api), r.token, timeout=3) for r in lab.lab.robots}
    one = clients["robot-1"]
    # the bench's system: Src's declared 1500MB leave robot-1 (2000MB) no room for Det, so Det
    # runs on another robot and its connection (its own loss bound: 15 %) crosses a link; only
    # the component_error rule, since Table III's communication failure would move everything
    # off the lossy robot by itself, and this test is about the connection's own bound
    system = bench_system(bound=15, sustain=SUSTAIN, min_interval=60)
    post_when_elected(one, "/v1/deploy", {"system": system}, 30.0)
    until(
        "Det ACTIVE on robot-2",
        lambda: det(one.get("/v1/status")),
        lambda d: d == ("robot-2", ACTIVE),
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    rows = until(
        "the connection's loss measured",
        lambda: one.get("/v1/status")["compliance"],
        lambda rs: any(r["constraint"] == "loss" and r["value"] is not None for r in rs),
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    (row,) = [r for r in rows if r["constraint"] == "loss"]
    assert (row["component"], row["subject"], row["robots"]) == (
        "Det",
        "Src.image->Det.image",
        ["robot-1", "robot-2"],
    )
    assert (row["bound"], row["must_be"], row["state"]) == (0.15, "below", "ok")
    assert events(clients, "compliance.violated") == []

    plan = lab.net
    assert plan is not None
    net.run(plan.loss("robot-2", 0.4, spare_host=True))  # robot-2's every link: 40 % each way
    violated = until(
        "compliance.violated for Det's link",
        lambda: events(clients, "compliance.violated"),
        bool,
        within=WITHIN,
        poll=POLL,
    )
    detail = violated[0]["detail"]
    assert (detail["component"], detail["constraint"], detail["robots"]) == (
        "Det",
        "loss",
        ["robot-1", "robot-2"],
    )
    assert detail["value"] >= 0.15
    assert detail["held_s"] >= SUSTAIN
    # re-placed by the allocator on the robot whose link to Src (pinned on robot-1) holds
    until(
        "Det ACTIVE on robot-3",
        lambda: det(one.get("/v1/status")),
        lambda d: d == ("robot-3", ACTIVE),
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    (move,) = events(clients, "compliance.move")
    assert move["detail"]["moved"] == {"Det": ["robot-2", "robot-3"]}
    assert "loss" in move["detail"]["reason"]
    # the placement changed: its old violation is cleared, the new link is judged
    cleared = events(clients, "compliance.cleared")
    assert any(e["detail"]["why"] == "placement changed" for e in cleared)
    status = one.get("/v1/status")
    (row,) = [r for r in status["compliance"] if r["constraint"] == "loss"]
    assert row["robots"] == ["robot-1", "robot-3"]
    assert row["state"] in ("ok", "unknown")
    det_row = next(c for c in status["components"] if c["component"] == "Det")
    assert det_row["compliance"] == "ok"
