"""The disconnect policy on real agents in network namespaces (root): a robot cut off from the
fleet (the allocator here) abdicates, stands its replaceable actives down and elects nobody,
keeps what the fleet may not replace, and after the heal no component is ACTIVE twice; a
`keep_original` component goes back to its robot."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.client import AgentClient, post_when_elected
from sdrpeer.errors import ApiError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.netlab import net
from sdrpeer.netlab.plan import PART_CHAIN
from sdrpeer.system.loader import parse_system
from tests.realnet import NETNS_ONLY
from tests.wait import until

pytestmark = pytest.mark.realnet
WITHIN, POLL = 30.0, 0.1
NOT_YET = (ApiError,)
"""An agent that is still starting answers with an API error: not yet."""

SYSTEM = """name: cut
components:
  - name: Cam
    target: components.camera:Camera
    params: {reserve_mb: 0, rate: 2, width: 32, height: 24}
    standby: {other_robots: 1}
    prefer: [robot-3]
  - name: Keep
    target: components.camera:Camera
    params: {reserve_mb: 0, rate: 2, width: 32, height: 24}
    prefer: [robot-3]
    disconnect: {replace: false}
  - name: Back
    target: components.camera:Camera
    params: {reserve_mb: 0, rate: 2, width: 32, height: 24}
    standby: {other_robots: 1}
    prefer: [robot-3]
    disconnect: {reconcile: keep_original}
"""


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:  # a namespace lab
    running = start_lab(
        UpOptions(3, tmp_path / "lab", preset="lan", netns=True, timeout=30), say=lambda _: None
    )
    try:
        yield running
    finally:
        running.stop(grace=3)
        assert net.load(tmp_path / "lab") is None


def actives(client: AgentClient) -> set[str]:
    """The components this robot runs ACTIVE as their active instance, by its own word."""
    try:
        rows: list[dict[str, Any]] = client.get("/v1/instances")
    except ApiError:
        return set()
    return {
        str(r["component"]) for r in rows if r.get("state") == "ACTIVE" and r["role"] == "active"
    }


def placed(status: dict[str, Any]) -> dict[str, str | None]:
    return {c["component"]: c["robot"] for c in status["components"]}


def story(client: AgentClient) -> str:
    """What a failure message adds: the robot's status and its latest events."""
    try:
        status = client.get("/v1/status")
        events = client.get("/v1/events")
    except ApiError as e:
        return f"(no status: {e})"
    comps = [(c["instance"], c["robot"], c["state"]) for c in status["components"]]
    tail = [(e["kind"], e.get("detail")) for e in events[-25:]]
    return f"allocator {status['allocator']}, plan {status['plan']}, {comps}; events {tail}"


def deploy_onto_robot_3(one: AgentClient, three: AgentClient) -> None:
    """Deploy the system through robot-1 and wait until robot-3 runs its three actives."""
    system = parse_system(SYSTEM, "cut.yaml").to_json()
    post_when_elected(one, "/v1/deploy", {"system": system}, 30.0)
    until(
        "actives on robot-3",
        lambda: actives(three),
        lambda a: a == {"Cam", "Keep", "Back"},
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
        context=lambda: f"robot-3: {story(three)}",
    )


@NETNS_ONLY
def test_a_robot_cut_off_stands_down_and_a_heal_finds_one_active_copy(lab: RunningLab) -> None:
    clients = {r.name: AgentClient(str(r.api), r.token, timeout=2) for r in lab.lab.robots}
    one, three = clients["robot-1"], clients["robot-3"]
    deploy_onto_robot_3(one, three)
    allocator = one.get("/v1/status")["allocator"]["name"]  # robot-3 (top priority) or not yet

    plan = lab.net
    assert plan is not None
    net.run(plan.partition([["robot-3"], ["robot-1", "robot-2"]]))
    # the side cut off: Cam and Back held INACTIVE, Keep (replace: false) running, no allocator
    until(
        "robot-3 standing Cam and Back down",
        lambda: actives(three),
        lambda a: a == {"Keep"},
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    status3 = three.get("/v1/status")
    assert status3["cut_off"] is True
    assert status3["allocator"]["name"] is None  # abdicated if it was the allocator
    # the fleet: Cam and Back active elsewhere, Keep still placed on robot-3
    fleet = until(
        "the fleet replacing Cam and Back",
        lambda: actives(one) | actives(clients["robot-2"]),
        lambda a: {"Cam", "Back"} <= a,
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    assert "Keep" not in fleet
    assert placed(one.get("/v1/status"))["Keep"] == "robot-3"
    assert one.get("/v1/status")["allocator"]["name"] in ("robot-1", "robot-2")
    assert allocator is not None
    assert three.get("/v1/status")["allocator"]["name"] is None  # and elects nobody

    net.run([plan.in_ns(r, "iptables", "-F", PART_CHAIN) for r in plan.names()])
    healed = time.monotonic()
    twice: list[tuple[float, str]] = []

    def rejoined() -> tuple[bool, bool]:
        """(cut off, holds the fleet's plan) of robot-3; notes every component ACTIVE twice."""
        seen = {name: actives(c) for name, c in clients.items()}
        twice.extend(
            (round(time.monotonic() - healed, 2), comp)
            for comp in ("Cam", "Keep", "Back")
            if sum(comp in a for a in seen.values()) > 1
        )
        status = three.get("/v1/status")
        return status["cut_off"], status["plan"] == one.get("/v1/status")["plan"]

    # until robot-3 is back in touch and holds the fleet's plan: Cam never ACTIVE twice
    until(
        "robot-3 back in touch, with the fleet's plan",
        rejoined,
        lambda seen: seen == (False, True),
        within=40,
        poll=0.05,
        retry=NOT_YET,
    )
    assert not any(comp == "Cam" for _, comp in twice), twice  # stood down: never two Cams
    assert "Cam" not in actives(three)
    # keep_original: Back goes back to robot-3 (a planned move, once robot-3's link is judged
    # sound again: the loss measured across the cut makes it degraded for a while)
    until(
        "Back moved back to robot-3",
        lambda: (placed(one.get("/v1/status"))["Back"], actives(three)),
        lambda x: x[0] == "robot-3" and "Back" in x[1],
        within=60,
        poll=POLL,
        retry=NOT_YET,
    )
    assert "Keep" in actives(three)  # never replaced, also not while robot-3 was degraded
    kinds = [e["kind"] for e in three.events(0, 1000)]
    assert kinds.index("fleet.cut_off") < kinds.index("fleet.rejoined")


@NETNS_ONLY
def test_an_agent_restarted_into_the_fleet_launches_nothing_from_its_old_plan(
    lab: RunningLab,
) -> None:
    """robot-3's agent is SIGKILLed (its hosts with it) and the fleet re-places its components;
    restarted with its data dir, it holds the old plan, yet it starts no host before it is in
    touch with the fleet and has the fleet's plan (a namespace lab: its address is kept)."""
    clients = {r.name: AgentClient(str(r.api), r.token, timeout=5) for r in lab.lab.robots}
    one, three = clients["robot-1"], clients["robot-3"]
    deploy_onto_robot_3(one, three)
    os.killpg(lab.procs["robot-3"].pid, signal.SIGKILL)
    lab.procs["robot-3"].wait(10)
    until(
        "the fleet re-placing Cam",
        lambda: placed(one.get("/v1/status")),
        lambda p: p["Cam"] not in (None, "robot-3"),
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    log = Path(lab.lab.robot("robot-3").log)  # type: ignore[union-attr]
    before = len(log.read_text().splitlines())
    lab.restart("robot-3")
    until(
        "robot-3 holding the fleet's plan",
        lambda: (three.get("/v1/status")["plan"], one.get("/v1/status")["plan"]),
        lambda p: p[0] is not None and p[0] == p[1],
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    until(
        "Keep (replace: false) back",
        lambda: actives(three),
        lambda a: "Keep" in a,
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    lines = log.read_text().splitlines()[before:]
    touch = next(i for i, line in enumerate(lines) if "fleet.in_touch" in line)
    started = [i for i, line in enumerate(lines) if "started pid" in line]
    assert started
    assert min(started) > touch, "\n".join(lines[: max(started) + 1])
    assert "Cam" not in actives(three)
