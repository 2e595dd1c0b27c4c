"""Recovery on real agents: components leave a robot whose signal fails (the allocator first, when
it sat there) and a robot whose agent is SIGKILLed; port data flows again after each move."""

from __future__ import annotations

import os
import signal
from functools import partial
from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster, http

pytestmark = pytest.mark.realnet

REPO = Path(__file__).resolve().parent.parent


def fast_system(tmp_path: Path) -> Path:
    """The paper's small system, with the communication-failure rule held for 2 s, not 6 s."""
    text = (REPO / "examples/paper/system-small.yaml").read_text()
    text = text.replace("../../profiles/", f"{REPO}/profiles/").replace("for: 6s", "for: 2s")
    path = tmp_path / "system.yaml"
    path.write_text(text)
    return path


def status(agent: Agent) -> dict[str, Any]:
    doc: dict[str, Any] = agent.get("/v1/status")
    return doc


def all_active_off(robot: str) -> Any:
    def ok(doc: dict[str, Any]) -> bool:
        comps = doc["components"]
        return bool(comps) and all(c["state"] == "active" and c["robot"] != robot for c in comps)

    return ok


def controller_poses(agent: Agent) -> int:
    rows = {i["component"]: i for i in agent.get("/v1/instances") if i.get("role") == "active"}
    ctl = rows.get("REDControllerRTC")
    return 0 if ctl is None else int(ctl["ports"].get("pose", {}).get("frames_in", 0))


def deploy(cluster: RealCluster, entry: Agent, path: Path) -> dict[str, Any]:
    cluster.wait_until(lambda: status(entry), lambda d: d["allocator"]["name"], "an allocator")
    from sdrpeer.system.loader import load_system  # noqa: PLC0415 - yaml and plugins

    doc = {"system": load_system(path).to_json()}
    code, body = cluster.wait_until(  # 503: a robot's record has not reached the allocator yet
        lambda: http("POST", entry.api + "/v1/deploy", doc, entry.token),
        lambda answer: answer[0] != 503,
        "the deploy answered",
    )
    assert code == 200, body
    return cluster.wait_until(
        lambda: status(entry),
        lambda d: bool(d["components"]) and all(c["state"] == "active" for c in d["components"]),
        "all ACTIVE",
    )


def test_signal_loss_on_the_allocators_robot_moves_the_allocator_first(
    cluster: RealCluster, tmp_path: Path
) -> None:
    (cluster.root / "robot-1.yaml").write_text(  # the highest priority: it holds the allocator
        "name: robot-1\nmemory: 4GB\ncpus: 4\nbattery: 100%\nposition: [0, 0]\nrssi: -45dBm\n"
        "priority: 10\n"
    )
    agents = cluster.start_many(3)
    one, two, three = agents
    cluster.wait_until(lambda: status(two), lambda d: d["allocator"]["name"] == "robot-1", "r1")
    doc = deploy(cluster, one, fast_system(tmp_path))
    placed = {c["robot"] for c in doc["components"]}
    assert placed == {"robot-1"}, cluster.logs()  # first_fit: the origin
    # on a loaded machine an election may be under way (name None): robot-1 must win it again
    before = cluster.wait_until(
        lambda: status(two)["allocator"], lambda a: a["name"] is not None, "a known allocator"
    )
    assert before["name"] == "robot-1", (
        f"the allocator left robot-1 before its signal fell: {before}"
    )
    epoch = before["epoch"]
    code, _ = http("POST", one.api + "/v1/robot", {"rssi": "-56dBm"}, one.token)
    assert code == 200
    cluster.wait_until(lambda: status(two), all_active_off("robot-1"), "moved off robot-1")
    after = cluster.wait_until(  # the election may still settle when the components are back
        lambda: status(two),
        lambda d: all_active_off("robot-1")(d) and d["allocator"]["name"] in ("robot-2", "robot-3"),
        "the allocator off robot-1",
    )
    assert after["allocator"]["epoch"] > epoch
    kinds = [e["kind"] for e in three.events()] + [e["kind"] for e in two.events()]
    assert "recovery.condition" in kinds
    assert "recovery.move" in kinds
    # the moved controller hears poses again, and robot-1 stopped what it ran
    ctl = next(c for c in after["components"] if c["component"] == "REDControllerRTC")
    host = {a.name: a for a in agents}[ctl["robot"]]
    n = cluster.wait_until(lambda: controller_poses(host), lambda v: v > 0, "poses after the move")
    cluster.wait_until(lambda: controller_poses(host), lambda v: v > n, "more poses")
    cluster.wait_until(lambda: one.get("/v1/instances"), lambda rows: rows == [], "robot-1 empty")


def test_a_killed_robots_components_come_up_elsewhere(cluster: RealCluster, tmp_path: Path) -> None:
    agents = cluster.start_many(3)
    one, two, _ = agents
    doc = deploy(cluster, one, fast_system(tmp_path))
    assert {c["robot"] for c in doc["components"]} == {"robot-1"}, explained(two, doc)
    listed = {i["name"] for i in two.member("robot-1")["instances"]}
    assert listed  # robot-1's record lists the actives it runs
    cluster.kill(one)
    # from the moment a survivor declares robot-1 dead, its view shows robot-1's instances lost
    for agent in agents[1:]:
        dead = cluster.wait_until(
            partial(agent.member, "robot-1"), lambda m: m["state"] == "dead", "robot-1 dead"
        )
        assert {i["name"] for i in dead["instances"]} == listed
        assert {i["state"] for i in dead["instances"]} == {"lost"}
    at_death = {
        r: [(i["name"], i["state"]) for i in a.member(r)["instances"]]
        for r, a in (("robot-2", two), ("robot-3", agents[2]))
    }
    after = cluster.wait_until(lambda: status(two), all_active_off("robot-1"), "moved", 20)
    standby_robots = {s["robot"] for c in doc["components"] for s in c["standbys"]}
    assert {c["robot"] for c in after["components"]} <= standby_robots, (  # hot standbys took over
        at_death,
        explained(two, after),
    )


def explained(agent: Agent, doc: dict[str, Any]) -> list[Any]:
    """How the allocator chose each active's robot, and what ruled the others out."""
    out = []
    for c in doc["components"]:
        d = agent.get(f"/v1/describe/{c['component']}")
        out += [(i["instance"], i["robot"], i["why"]) for i in d["instances"]]
    return out


CRASHY = """\
name: crashy
components:
  - name: Pub
    target: tests.components_fixture:Counter
    params: {rate: 50}
    standby: {same_robot: 1, mode: hot}
  - name: Rec
    target: tests.components_fixture:Recorder
connections:
  - {from: Pub.out, to: Rec.inp}
recovery:
  rules:
    - cause: component_error
      actions: [standby_same_robot, restart, standby_other_robot, launch_other_robot]
"""


def test_a_crashed_host_is_replaced_by_its_same_robot_standby(
    cluster: RealCluster, tmp_path: Path
) -> None:
    agents = cluster.start_many(2)
    one = agents[0]
    path = tmp_path / "crashy.yaml"
    path.write_text(CRASHY)

    def ready(d: dict[str, Any]) -> bool:
        comps = d["components"]
        return bool(comps) and all(
            c["state"] == "active" and all(s["state"] == "inactive" for s in c["standbys"])
            for c in comps
        )

    deploy(cluster, one, path)
    cluster.wait_until(lambda: status(one), ready, "standby ready")
    rows = {i["name"]: i for i in one.get("/v1/instances")}
    os.kill(rows["Pub"]["pid"], signal.SIGKILL)

    def replaced(d: dict[str, Any]) -> bool:
        pub = d["components"][0]
        return pub["instance"] == "Pub-s1" and pub["state"] == "active" and ready(d)

    doc = cluster.wait_until(lambda: status(one), replaced, "the standby active, a new standby")
    pub = doc["components"][0]
    assert pub["robot"] == "robot-1"  # standby on the same robot first (Table III)
    assert pub["standbys"][0]["instance"] == "Pub-s2"
    decisions = [e for e in one.events() if e["kind"] == "recovery.decision"]
    assert decisions[0]["detail"]["action"] == "standby_same_robot"

    def received() -> int:
        rows = {i["name"]: i for i in one.get("/v1/instances")}
        return int(rows["Rec"]["ports"].get("inp", {}).get("frames_in", 0))

    n = received()
    cluster.wait_until(received, lambda v: v > n, "frames from the new Pub")


HANGS = """\
name: hangs
components:
  - name: Pub
    target: tests.components_fixture:Sleeper
    params: {{trigger: "{trigger}"}}
    standby: {{same_robot: 1, mode: hot}}
    watchdog: 3s
recovery:
  rules:
    - cause: component_error
      actions: [standby_same_robot, restart, standby_other_robot, launch_other_robot]
"""


@pytest.mark.parametrize("how", ["sigstop", "blocked_on_execute"])
def test_a_hung_host_is_killed_by_its_watchdog_and_its_standby_takes_over(
    cluster: RealCluster, tmp_path: Path, how: str
) -> None:
    """A host that stops answering (SIGSTOP, or a component stuck inside on_execute) is killed
    once its watchdog runs out (3 s here: a heartbeat late on a loaded machine must not count)
    and treated like a crash: the same-robot standby becomes ACTIVE; the agent's event says the
    host was hung."""
    one = cluster.start_many(1)[0]
    trigger = tmp_path / "block"
    path = tmp_path / "hangs.yaml"
    path.write_text(HANGS.format(trigger=trigger))
    deploy(cluster, one, path)

    def ready(d: dict[str, Any]) -> bool:
        c = d["components"][0]
        return c["state"] == "active" and [s["state"] for s in c["standbys"]] == ["inactive"]

    cluster.wait_until(lambda: status(one), ready, "standby ready")
    pid = {i["name"]: i for i in one.get("/v1/instances")}["Pub"]["pid"]
    if how == "sigstop":
        os.kill(pid, signal.SIGSTOP)
    else:
        trigger.write_text("Pub\n")

    def replaced(d: dict[str, Any]) -> bool:
        c = d["components"][0]
        return bool(c["instance"] == "Pub-s1" and c["state"] == "active")

    cluster.wait_until(lambda: status(one), replaced, "the standby active")
    faults = [e["detail"] for e in one.events() if e["kind"] == "instance.fault"]
    assert any(f["instance"] == "Pub" and f["detail"].startswith("hung: ") for f in faults), faults
    cluster.wait_until(lambda: _gone(pid), bool, "the hung host gone, not left stopped")


def _gone(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] == "Z"  # killed, not yet reaped
    except OSError:
        return True


def test_hostile_bodies_are_refused_and_change_nothing(
    cluster: RealCluster, tmp_path: Path
) -> None:
    """The issue's hostile inputs on a real agent: each a 400 (or 404) naming the field, the plan
    and the robot's record untouched, every view still answering."""
    one = cluster.start_many(1)[0]
    path = tmp_path / "crashy.yaml"
    path.write_text(CRASHY)
    before = deploy(cluster, one, path)["plan"]
    cases: list[tuple[str, Any, int, str]] = [
        (
            "/v1/recovery",
            {"robot": [], "component": {}, "instance": 1, "action": None},
            400,
            "field 'robot': expected a name",
        ),
        (
            "/v1/recovery",
            {"robot": "robot-1", "component": "Pub", "instance": "Pub", "action": "explode"},
            400,
            "field 'action': expected one of",
        ),
        (
            "/v1/recovery",
            {
                "robot": "robot-1",
                "component": "Nope",
                "instance": "x",
                "action": "standby_same_robot",
            },
            404,
            "no component 'Nope'",
        ),
        ("/v1/deploy", {"system": {"name": "x"}}, 400, "not a system document: no field"),
        ("/v1/deploy", {"system": 5}, 400, "field 'system': missing, or not an object"),
        ("/v1/robot", {"rssi": "-1000dBm"}, 400, "'-1000dBm' is out of range (-150dBm to 0dBm)"),
        ("/v1/robot", {"pos": ["1e308", "-1e308"]}, 400, "is out of range"),
        ("/v1/robot", {"memory": "1000000TB"}, 400, "is out of range (1MB to 1PiB)"),
    ]
    for route, body, code, message in cases:
        status_code, answer = http("POST", one.api + route, body, one.token)
        assert status_code == code, (route, body, answer)
        assert message in answer["error"], (route, answer)
        assert "Error" not in answer["error"], answer  # the project's words, not Python's
    assert status(one)["plan"] == before
    me = one.member("robot-1")  # still encodes and answers
    assert me["metrics"]["rssi_dbm"] == -45.0
