"""Security on real agents (docs/security.md): keys rotate with no downtime (add the new key
everywhere, sign with it, retire the old: SIGHUP re-reads the key file), a robot left with only
the retired key is locked out, no state-changing route answers without a token, and without a
key (`--insecure`) no token is a constant."""

from __future__ import annotations

import hashlib
import hmac
import os
import signal
import sys
from functools import partial
from pathlib import Path

import pytest

from sdrpeer.agent.files import SEQ_RESERVE, seq_start
from sdrpeer.config import AgentConfig
from sdrpeer.gossip.wire import format_key
from sdrpeer.keys.keyring import Keyring
from tests.realnet import Agent, RealCluster, http
from tests.test_recovery_e2e import CRASHY, deploy

pytestmark = pytest.mark.realnet


def rotate(cluster: RealCluster, agents: list[Agent], keys: list[bytes]) -> None:
    """Write the shared key file and make every agent re-read it."""
    cluster.key_file.write_text("".join(format_key(k) + "\n" for k in keys))
    for agent in agents:
        os.kill(agent.pid, signal.SIGHUP)
    want = [Keyring([k]).key_ids[0].hex() for k in keys]

    def reloaded(agent: Agent) -> bool:
        done = [e for e in agent.events() if e["kind"] == "keys.reloaded"]
        return bool(done) and done[-1]["detail"]["key_ids"] == want

    for agent in agents:
        cluster.wait_until(partial(reloaded, agent), bool, f"{agent.name} reloaded")


def test_keys_rotate_with_no_downtime_and_the_old_key_is_locked_out(
    cluster: RealCluster, tmp_path: Path
) -> None:
    agents = cluster.start_many(3)
    before = {a.name: a.agent_info()["rejected"] for a in agents}
    old, new = cluster.key, Keyring.generate()
    # each step holds until gossip flowed under it (fast_test: ~20 messages/s into each agent)
    rotate(cluster, agents, [old, new])  # 1. everyone knows the new key, still signs with old
    cluster.wait_traffic(agents, 10, "signed with the old key")
    rotate(cluster, agents, [new, old])  # 2. everyone signs with the new key
    cluster.wait_traffic(agents, 10, "signed with the new key")
    rotate(cluster, agents, [new])  # 3. the old key is retired
    cluster.wait_traffic(agents, 20, "the old key retired")
    names = {a.name for a in agents}
    for agent in agents:
        assert {n: s for n, s in agent.states().items() if n in names} == dict.fromkeys(
            names, "alive"
        )
        # no downtime: not one datagram was refused for its key during the rotation, and no one
        # died (a suspicion alone can come from a loaded machine at any time, keys or not)
        rejected = agent.agent_info()["rejected"]
        for reason in ("unauthenticated", "unknown_key"):
            assert rejected[reason] == before[agent.name][reason], (agent.name, reason)
        assert "member.dead" not in {e["kind"] for e in agent.events()}, agent.name
    # agents still talk to each other with the new peer tokens: a deploy goes everywhere
    path = tmp_path / "crashy.yaml"
    path.write_text(CRASHY)
    deploy(cluster, agents[1], path)
    # a robot that missed the rotation holds only the retired key: it cannot join
    stale_key = tmp_path / "stale.key"
    stale_key.write_text(format_key(old) + "\n")
    cluster.key_file, kept = stale_key, cluster.key_file
    refused = agents[0].agent_info()["rejected"]["unknown_key"]
    outsider = cluster.start("robot-9", join=[agents[0]])
    cluster.key_file = kept
    cluster.wait_until(  # its datagrams arrive, and are refused
        lambda: agents[0].agent_info()["rejected"]["unknown_key"],
        lambda n: n >= refused + 3,
        "robot-1 refusing robot-9's retired key",
    )
    assert "robot-9" not in agents[0].states()
    assert outsider.states().get("robot-1") != "alive"


STATE_CHANGING = [
    ("POST", "/v1/deploy", {"system": {}}),
    ("POST", "/v1/undeploy", {}),
    ("POST", "/v1/plan", {"plan": {}}),
    ("POST", "/v1/recovery", {}),
    ("POST", "/v1/move", {"component": "x"}),
    ("POST", "/v1/robot", {"rssi": "-80dBm"}),
    ("POST", "/v1/instances", {"instances": []}),
    ("DELETE", "/v1/instances/x", None),
    ("POST", "/v1/instances/x/restart", None),
    ("GET", "/v1/plan", None),  # the plan is only for peers and the operator
]


def test_no_state_change_without_the_token_and_loopback_by_default(cluster: RealCluster) -> None:
    assert AgentConfig(name="r").api.startswith("127.0.0.1:")
    agent = cluster.start("robot-1")
    assert agent.api.startswith("http://127.0.0.1:")
    before = agent.member("robot-1")["metrics"]["rssi_dbm"]
    for method, path, body in STATE_CHANGING:
        for token in (None, "wrong-token"):
            code, doc = http(method, agent.api + path, body, token)
            assert code == 401, (method, path, token, doc)
    code, _ = http("POST", agent.api + "/v1/state", None, None)  # msgpack body: none at all
    assert code == 401
    assert agent.member("robot-1")["metrics"]["rssi_dbm"] == before  # nothing changed
    code, _ = http("POST", agent.api + "/v1/robot", {"rssi": "-80dBm"}, agent.token)
    assert code == 200


def test_robots_with_clocks_an_hour_apart_form_one_fleet(cluster: RealCluster) -> None:
    """No NTP on the Moon: robot-2's clock is an hour slow, robot-3's an hour fast. Both join,
    everyone ends on the fastest clock, and nobody is refused as stale any more."""
    for name, skew in (("robot-2", "-1h"), ("robot-3", "1h")):
        (cluster.root / f"{name}.yaml").write_text(
            f"name: {name}\nmemory: 4GB\ncpus: 4\nbattery: 100%\nrssi: -45dBm\nclock_skew: {skew}\n"
        )
    agents = cluster.start_many(3)
    offsets = {a.name: a.agent_info()["clock"]["offset_ms"] for a in agents}
    assert offsets["robot-3"] < 5_000  # the fastest clock: its own time is the fleet's
    assert 3_595_000 < offsets["robot-1"] < 3_605_000
    assert 7_195_000 < offsets["robot-2"] < 7_205_000
    stale = {a.name: a.agent_info()["rejected"]["stale"] for a in agents}
    cluster.wait_traffic(agents, 30, "after the clocks agreed")
    # the counters only grow: equal now means not one stale refusal in all that traffic
    assert {a.name: a.agent_info()["rejected"]["stale"] for a in agents} == stale
    assert all(set(a.states().values()) == {"alive"} for a in agents)


def test_gossip_seqs_keep_rising_across_restarts_even_when_the_clock_went_back(
    tmp_path: Path,
) -> None:
    first = seq_start(tmp_path, 5_000_000)
    assert first == 5_000_000
    again = seq_start(tmp_path, 1_000)  # restarted with a clock far behind
    assert again == first + SEQ_RESERVE  # above anything the first run could have used
    assert seq_start(tmp_path, again + 10 * SEQ_RESERVE) == again + 10 * SEQ_RESERVE
    (tmp_path / "seq.floor").write_text("garbage")
    assert seq_start(tmp_path, 7) == 7  # an unreadable floor: the clock alone


def test_insecure_agents_take_no_constant_token_and_say_what_is_exposed(
    cluster: RealCluster,
) -> None:
    """Without a key the peer token once was HMAC-SHA256 of a fixed label under an empty key: a
    public constant that opened every route, an `exec` launch included. Now an insecure agent
    takes no peer token at all (not even its insecure peers'), only its own random API token."""
    first = cluster.start("robot-1", insecure=True)
    second = cluster.start("robot-2", join=[first], insecure=True)
    cluster.wait_states(first, {"robot-1": "alive", "robot-2": "alive"}, what="an insecure fleet")
    constant = hmac.new(b"", b"sdrpeer peer api v1", hashlib.sha256).hexdigest()
    shell = {
        "instances": [
            {"name": "sh", "launcher": "exec", "target": ["/bin/sh", "-c", "touch pwned"]}
        ]
    }
    for agent in (first, second):
        for method, path, body in [*STATE_CHANGING, ("POST", "/v1/instances", shell)]:
            code, doc = http(method, agent.api + path, body, constant)
            assert code == 401, (agent.name, method, path, doc)
        assert not list(cluster.root.rglob("pwned"))
        assert agent.agent_info()["insecure"] is True
        log = agent.log.read_text()
        assert "INSECURE" in log
        assert "robots cannot authenticate each other" in log
        code, _ = http("GET", agent.api + "/v1/plan", None, agent.token)
        assert code == 200  # the operator's own token still works


def test_exec_is_off_unless_configured_and_never_placed_where_refused(
    cluster: RealCluster, tmp_path: Path
) -> None:
    """robot-1 runs with the default launch policy (python only), robot-2 allows exec. A spec
    robot-1 refuses is answered 403 naming the setting, and nothing changes; the allocator
    places an exec component on robot-2, the robot that gossips that it takes it."""
    first = cluster.start("robot-1")
    cluster.start("robot-2", join=[first], flags=["--allow-launcher", "exec"])
    cluster.wait_states(first, {"robot-1": "alive", "robot-2": "alive"}, what="two robots")
    host = [sys.executable, str(Path(__file__).with_name("fake_host.py"))]
    spec = {"instances": [{"name": "Sh", "launcher": "exec", "target": host}]}
    code, doc = http("POST", first.api + "/v1/instances", spec, first.token)
    assert code == 403, doc
    assert "launcher 'exec' is off on this robot" in doc["error"]
    assert "allow_launchers: [exec] (or --allow-launcher exec)" in doc["error"]
    assert first.get("/v1/instances") == []  # nothing was added
    cluster.wait_until(
        lambda: (first.members()["robot-2"]["launch"] or {}).get("launchers"),
        lambda launchers: launchers == ["python", "exec"],
        "robot-2's launch policy in robot-1's table",
    )
    path = tmp_path / "shell.yaml"
    target = ", ".join(host)
    path.write_text(
        f"name: sh\ncomponents:\n  - {{name: Sh, launcher: exec, target: [{target}]}}\n"
    )
    doc = deploy(cluster, first, path)
    assert [(c["component"], c["robot"]) for c in doc["components"]] == [("Sh", "robot-2")]
