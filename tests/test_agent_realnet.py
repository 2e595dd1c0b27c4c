"""Real agents on loopback: discovery, failure detection, restart, leave, hostile datagrams, API.

Every test starts its own three `sdrpeer agent` processes (preset fast_test, gossip and API on
127.0.0.1 port 0, one fresh cluster key) through `tests.realnet`, waits with bounded polls, and
kills every process at teardown, pass or fail.
"""

from __future__ import annotations

import json
import os
import random
import subprocess
import sys
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path

import pytest

from sdrpeer.gossip.messages import Gossip
from sdrpeer.gossip.wire import Codec, Keyring
from tests.realnet import REPO, Agent, RealCluster, http, send_udp

pytestmark = pytest.mark.realnet

RESTART_BOUND = 5.0  # a restarted robot must be alive again at every peer within this (seconds)
PROPAGATION_BOUND = 5.0  # a record change or a trap must reach another robot within this


@pytest.fixture
def trio(cluster: RealCluster) -> list[Agent]:
    """robot-1..3, converged (each sees all three alive)."""
    return cluster.start_many(3)


def test_three_agents_find_each_other(cluster: RealCluster, trio: list[Agent]) -> None:
    by_name = {a.name: a for a in trio}
    for agent in trio:
        members = agent.members()
        assert sorted(members) == ["robot-1", "robot-2", "robot-3"], agent.name
        for name, m in members.items():
            assert m["state"] == "alive", (agent.name, m)
            assert m["addr"] == by_name[name].gossip, (agent.name, m)
        info = agent.agent_info()
        assert info["members"]["alive"] == 3
        assert info["insecure"] is False
        assert info["rejected"] == {} or not any(info["rejected"].values()), info["rejected"]
    # Records travel too: robot-3 knows robot-1's API address from gossip alone.
    cluster.wait_until(
        trio[2].members,
        lambda ms: ms["robot-1"]["api"] == trio[0].api,
        "robot-3 to learn robot-1's api from its record",
    )


def test_kill_9_is_marked_dead(cluster: RealCluster, trio: list[Agent]) -> None:
    one, two, three = trio
    start = time.monotonic()
    cluster.kill(three)
    for agent in (one, two):
        cluster.wait_states(agent, {"robot-3": "dead", "robot-1": "alive", "robot-2": "alive"})
    elapsed = time.monotonic() - start
    assert elapsed < 10.0, f"death took {elapsed:.1f} s to be seen by both survivors"
    for agent in (one, two):
        kinds = [e["kind"] for e in agent.events() if e["robot"] == "robot-3"]
        assert "member.left" not in kinds, (agent.name, kinds)


def test_restarted_robot_is_alive_again_at_its_new_address(
    cluster: RealCluster, trio: list[Agent]
) -> None:
    one, two, three = trio
    alive_at = {a.name: a.member("robot-3")["incarnation"] for a in (one, two)}
    cluster.kill(three)
    held: dict[str, int] = {}
    for agent in (one, two):
        members = cluster.wait_states(agent, {"robot-3": "dead"}, "before the restart")
        held[agent.name] = members["robot-3"]["incarnation"]
        # a death is declared at the incarnation the survivor knew, or a later one: never older
        assert held[agent.name] >= alive_at[agent.name]

    again = cluster.start("robot-3", join=[one], run=1)  # new port, fresh data dir, incarnation 0
    start = time.monotonic()  # from the moment it answers (its start-up is not the protocol's)
    assert again.gossip != three.gossip
    assert again.api != three.api
    for agent in (one, two):
        left = max(0.1, RESTART_BOUND - (time.monotonic() - start))
        seen = cluster.wait_until(
            partial(agent.member, "robot-3"),
            lambda m: m["state"] == "alive" and m["addr"] == again.gossip,
            f"{agent.name} to see the restarted robot-3 alive at {again.gossip}",
            timeout=left,
        )
        assert seen["incarnation"] > held[agent.name], seen
    elapsed = time.monotonic() - start
    assert elapsed < RESTART_BOUND, f"restart took {elapsed:.2f} s to be seen"
    # The new life's record (new API address) supersedes the old one everywhere.
    for agent in (one, two):
        cluster.wait_until(
            partial(agent.member, "robot-3"),
            lambda m: m["api"] == again.api,
            f"{agent.name} to show robot-3's new api {again.api}",
            timeout=RESTART_BOUND,
        )
    cluster.wait_states(again, dict.fromkeys(("robot-1", "robot-2", "robot-3"), "alive"))


def test_sigterm_is_seen_as_left_not_dead(cluster: RealCluster, trio: list[Agent]) -> None:
    one, two, three = trio
    code = cluster.terminate(three)
    assert code == 0, f"graceful stop exited with {code}"
    assert not (three.data_dir / "agent.json").exists(), "agent.json left behind after stop"
    for agent in (one, two):
        cluster.wait_states(agent, {"robot-3": "left"}, "graceful leave")
        kinds = [e["kind"] for e in agent.events() if e["robot"] == "robot-3"]
        assert "member.left" in kinds, (agent.name, kinds)
        assert "member.dead" not in kinds, (agent.name, kinds)
        assert agent.members()["robot-3"]["state"] == "left"


def _rejected(agent: Agent) -> dict[str, int]:
    return dict(agent.agent_info()["rejected"])


def _counted(reason: str, before: dict[str, int]) -> Callable[[dict[str, int]], bool]:
    return lambda counts: counts.get(reason, 0) > before.get(reason, 0)


def test_hostile_datagrams_are_rejected_and_counted(
    cluster: RealCluster, trio: list[Agent]
) -> None:
    target = trio[0]
    addr = target.gossip_addr
    now = time.time()
    wrong_key = Codec("intruder", Keyring([Keyring.generate()])).encode(Gossip("intruder"), now)
    valid = Codec("replayer", Keyring([cluster.key])).encode(Gossip("replayer"), now)
    noise = b"\x00" + random.Random(7).randbytes(199)  # cannot start with the b"SP" magic
    unsigned = Codec("plain", None).encode(Gossip("plain"), now)

    before = _rejected(target)
    accepted_before = target.agent_info()["messages"]["in"]
    cases = [
        ("unknown_key", [wrong_key]),
        ("replayed", [valid, valid]),
        ("malformed", [noise]),
        ("unauthenticated", [unsigned]),
    ]
    for reason, datagrams in cases:
        send_udp(addr, *datagrams)
        counts = cluster.wait_until(
            lambda: _rejected(target),
            _counted(reason, before),
            f"robot-1 to count a datagram under rejected[{reason}]",
            timeout=5.0,
        )
        assert counts[reason] == before.get(reason, 0) + 1, (reason, counts)
    final = _rejected(target)
    expected = {r: before.get(r, 0) + 1 for r, _ in cases}
    assert {r: final.get(r, 0) for r in expected} == expected
    others = {r: n for r, n in final.items() if r not in expected and n != before.get(r, 0)}
    assert others == {}, f"unexpected rejections: {others}"
    assert target.agent_info()["messages"]["in"] >= accepted_before + 5
    # Still running, still in the cluster.
    assert target.running()
    cluster.wait_states(target, dict.fromkeys(("robot-1", "robot-2", "robot-3"), "alive"))
    assert "replayer" not in target.members()
    assert "Traceback" not in target.log.read_text()


def test_api_needs_the_token_and_changes_travel_by_gossip(
    cluster: RealCluster, trio: list[Agent]
) -> None:
    one, two, _ = trio
    url = one.api + "/v1/robot"
    status, body = http("POST", url, {"rssi": "-55dBm"})
    assert status == 401, body
    status, body = http("POST", url, {"rssi": "-55dBm"}, token="not-the-token")
    assert status == 401, body
    assert one.members()["robot-1"]["metrics"]["rssi_dbm"] == -45.0, "refused call had an effect"

    status, body = http("POST", url, {"rssi": "-55dBm"}, token=one.token)
    assert status == 200, body
    assert body["name"] == "robot-1"
    assert body["metrics"]["rssi_dbm"] == -55.0
    cluster.wait_until(
        partial(two.member, "robot-1"),
        lambda m: (m["metrics"] or {}).get("rssi_dbm") == -55.0,
        "robot-2 to see robot-1 at -55 dBm",
        timeout=PROPAGATION_BOUND,
    )


def test_a_change_inside_the_cuts_travels_as_vitals_not_as_a_record(
    cluster: RealCluster, trio: list[Agent]
) -> None:
    """A battery at 90 % is no decision input (no rule, no trap cut between): robot-2 sees it
    through robot-1's vitals on its pings, under the record version it already held. Another
    input (the election settling after start) may make a new record inside the window, so up to
    three changes are tried; a battery change that made a record would do so every time."""
    one, two, _ = trio
    for attempt in range(3):
        version = cluster.wait_until(
            partial(two.member, "robot-1"),
            lambda m: m["record_version"] > 0,
            "robot-2 to hold robot-1's record",
        )["record_version"]
        battery = 90.0 - attempt
        status, body = http(
            "POST", one.api + "/v1/robot", {"battery": f"{battery:g}%"}, token=one.token
        )
        assert status == 200, body
        seen = cluster.wait_until(
            partial(two.member, "robot-1"),
            lambda m, b=battery: (
                (m["metrics"] or {}).get("battery_pct") == pytest.approx(b, abs=0.2)
            ),  # type: ignore[misc]
            f"robot-2 to see robot-1's battery at {battery:g} %",
            timeout=PROPAGATION_BOUND,
        )
        if seen["record_version"] == version:
            break
    assert seen["record_version"] == version, "every battery change made a new record"
    assert seen["vitals_revision"] >= 1
    info = one.agent_info()
    assert info["published"]["vitals"] >= 1
    assert info["messages"]["sent_by_kind"]["ping"] > 0
    assert info["messages"]["sent_by_kind"]["vitals"] > 0


def _battery_traps(agent: Agent) -> list[dict[str, object]]:
    return [
        e
        for e in agent.events()
        if e["kind"] == "trap"
        and e["robot"] == "robot-1"
        and e["detail"].get("metric") == "battery_pct"
    ]


def test_low_battery_trap_reaches_another_robot(cluster: RealCluster, trio: list[Agent]) -> None:
    one, two, _ = trio
    assert _battery_traps(two) == []
    status, body = http("POST", one.api + "/v1/robot", {"battery": "10%"}, token=one.token)
    assert status == 200, body
    traps = cluster.wait_until(
        lambda: _battery_traps(two),
        bool,
        "robot-2's event log to show robot-1's battery trap",
        timeout=PROPAGATION_BOUND,
    )
    detail = traps[0]["detail"]
    assert isinstance(detail, dict)
    assert detail["state"] == "raised"
    assert detail["value"] == pytest.approx(10.0, abs=0.1)
    assert detail["threshold"] == 20.0


def test_cli_members_json(cluster: RealCluster, trio: list[Agent], tmp_path: Path) -> None:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
    env.pop("SDRPEER_API", None)
    env.pop("SDRPEER_TOKEN", None)
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", "members", "--json", "--api", trio[1].api],
        capture_output=True,
        text=True,
        timeout=15,
        env=env,
        cwd=tmp_path,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    members = json.loads(done.stdout)
    assert isinstance(members, list)
    assert [m["name"] for m in members] == ["robot-1", "robot-2", "robot-3"]
    assert {m["state"] for m in members} == {"alive"}
    assert {m["addr"] for m in members} == {a.gossip for a in trio}


def test_the_highest_priority_robot_is_elected_when_it_starts_last(tmp_path: Path) -> None:
    """The lan preset's timings, an idle fleet: the last robot to start has the highest priority
    and must end up the allocator (its election clock starts when its stack loads, not at the
    next idle tick: a quiet fleet may not wake it for seconds), by the first claim or by one
    handover at start (the priority window)."""
    lab = RealCluster(tmp_path / "net", preset="lan")
    try:
        for name in ("robot-1", "robot-2"):
            lab.robot_file(name)
        top = lab.robot_file("robot-3")
        top.write_text(top.read_text() + "priority: 10\n")
        one = lab.start("robot-1")
        # the other two side by side: robot-3 must join within robot-1's startup grace, which
        # two agent starts one after the other overran on a loaded machine
        spawned = [lab.spawn(name, join=[one]) for name in ("robot-2", "robot-3")]
        two, three = (lab.started(agent) for agent in spawned)
        for agent in (one, two, three):
            doc = lab.wait_until(
                partial(agent.get, "/v1/status"),
                lambda d: d["allocator"]["name"] == "robot-3",
                "robot-3 the allocator",
                20,
            )
            # the first claim or, when robot-1 claimed before robot-3's record reached it (a
            # loaded machine), one handover within robot-3's priority window
            assert doc["allocator"]["epoch"] in (1, 2), (agent.name, doc["allocator"])
    finally:
        lab.close()


def test_a_higher_priority_robot_started_after_the_election_takes_the_role_once(
    tmp_path: Path,
) -> None:
    """Priority counts at start (`ElectionConfig.priority_window`): robot-3 (priority 10) starts
    after robot-1 and robot-2 have elected one of them; within its first seconds it takes the
    role, once, at the next epoch, and every robot follows it; the old allocator stepped down
    outranked."""
    lab = RealCluster(tmp_path / "net", preset="lan")
    try:
        for name in ("robot-1", "robot-2"):
            lab.robot_file(name)
        top = lab.robot_file("robot-3")
        top.write_text(top.read_text() + "priority: 10\n")
        one = lab.start("robot-1")
        two = lab.start("robot-2", join=[one])
        first = lab.wait_until(
            lambda: (one.get("/v1/status")["allocator"], two.get("/v1/status")["allocator"]),
            lambda pair: pair[0]["name"] is not None and pair[0] == pair[1],
            "one allocator both know",
            30,
        )[0]
        old = {"robot-1": one, "robot-2": two}[first["name"]]
        three = lab.start("robot-3", join=[one])
        for agent in (one, two, three):
            doc = lab.wait_until(
                partial(agent.get, "/v1/status"),
                lambda d: d["allocator"]["name"] == "robot-3",
                "robot-3 took the role",
                30,
            )
            # the next epoch; or, on a loaded machine, robot-3 claimed before it heard the
            # fleet's allocator, at the same epoch, and its higher rank won there
            assert doc["allocator"]["epoch"] in (first["epoch"], first["epoch"] + 1), doc
        stepped = [e for e in old.events() if e["kind"] == "election.stepped_down"]
        assert [e["detail"]["reason"] for e in stepped] == ["outranked"]
        claims = [e for e in three.events() if e["kind"] == "election.elected"]
        assert len(claims) == 1
    finally:
        lab.close()
