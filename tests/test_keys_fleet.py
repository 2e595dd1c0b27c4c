"""Key commands on a real 5-robot lab: `sdrpeer keygen` and `sdrpeer key add|primary|retire`
rotate the running fleet with no suspicion, no death and no refused datagram; a change that
would lock a robot out is refused and changes nothing; a restarted robot keeps the new ring."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest

from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError
from sdrpeer.keys.keyring import Keyring, key_id
from sdrpeer.lab.up import RunningLab, UpOptions, read_agent_json, start_lab
from tests.wait import until

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tools"))

from bench_keys import cli, rotate  # noqa: E402

pytestmark = pytest.mark.realnet
ROBOTS = 5


@pytest.fixture(scope="module")
def lab(tmp_path_factory: pytest.TempPathFactory) -> Iterator[RunningLab]:
    root = tmp_path_factory.mktemp("keys")
    running = start_lab(
        UpOptions(ROBOTS, root / "lab", preset="lan", timeout=90), say=lambda _: None
    )
    try:
        yield running
    finally:
        running.stop(grace=5)


def ring_of(lab: RunningLab, robot: str) -> dict[str, object]:
    entry = lab.lab.robot(robot)
    assert entry is not None
    return dict(AgentClient(str(entry.api), entry.token, timeout=5).get("/v1/keys"))


def test_keygen_prints_a_key_the_agent_reads(tmp_path: Path) -> None:
    code, text, _ = cli(tmp_path, "keygen")
    assert code == 0, text
    path = tmp_path / "new.key"
    path.write_text(text)
    ring = Keyring.from_file(path)
    assert len(ring.signing_key) == 32
    assert cli(tmp_path, "keygen")[1] != text  # a new one each time


def test_the_fleet_rotates_with_no_suspicion_and_keeps_its_keys(
    lab: RunningLab, tmp_path: Path
) -> None:
    first = rotate(lab, tmp_path, settle=3.0)
    assert first["robots_on_new_key"] == ROBOTS, first
    assert set(first["alive_seen_after"].values()) == {ROBOTS}, first  # on the new key alone
    assert first["bad_events"] == [], first  # no member ever SUSPECT or DEAD
    assert first["rejected"] == {"unauthenticated": 0, "unknown_key": 0}, first
    new_id = first["new_key_id"]
    assert ring_of(lab, "robot-4") == {"name": "robot-4", "primary": new_id, "keys": [new_id]}
    # the ring each agent uses is saved in its data dir: a restart keeps it (the lab's key
    # file still holds only the retired key: the robot could not rejoin with that)
    entry = lab.lab.robot("robot-3")
    assert entry is not None
    saved = Keyring.from_file(Path(entry.data_dir) / "keyring")
    assert [key_id(k).hex() for k in saved.keys] == [new_id]
    lab.procs["robot-3"].send_signal(signal.SIGTERM)
    lab.procs["robot-3"].wait(timeout=30)
    lab.restart("robot-3")
    restarted = until(
        "robot-3's new API address",
        lambda: read_agent_json(entry.data_dir),
        lambda info: info is not None and info.get("pid") == lab.procs["robot-3"].pid,
        within=60,
        poll=0.2,
    )
    assert restarted is not None
    until(
        "robot-3 alive again for robot-1",
        lambda: {
            m["name"]: m["state"]
            for m in AgentClient(str(lab.lab.robots[0].api), timeout=3).members()
        },
        lambda s: s.get("robot-3") == "alive",
        within=60,
        poll=0.2,
        retry=(ApiError,),
    )
    again = AgentClient(str(restarted["api"]), entry.token, timeout=5).get("/v1/keys")
    assert again["primary"] == new_id


def test_changes_that_would_lock_a_robot_out_are_refused(lab: RunningLab, tmp_path: Path) -> None:
    before = json.loads(cli(lab.lab_dir, "key", "list", "--json")[1])
    primary = before["robots"]["robot-1"]["primary"]
    code, text, _ = cli(lab.lab_dir, "key", "retire", primary)
    assert code == 1, text
    assert "409" in text
    assert "make another key primary" in text
    unknown = key_id(Keyring.generate()).hex()
    code, text, _ = cli(lab.lab_dir, "key", "primary", unknown)
    assert code == 1, text
    assert "install it first" in text or "does not hold" in text
    code, text, _ = cli(lab.lab_dir, "key", "primary", "nothex")
    assert code == 2, text
    assert json.loads(cli(lab.lab_dir, "key", "list", "--json")[1]) == before


def test_key_routes_need_the_token(lab: RunningLab) -> None:
    api = str(lab.lab.robots[1].api)
    for method, path, body in (
        ("GET", "/v1/keys", None),
        ("GET", "/v1/keys/fleet", None),
        ("POST", "/v1/keys", {"op": "retire", "key_id": "00000000"}),
        ("POST", "/v1/keys/fleet", {"op": "retire", "key_id": "00000000"}),
    ):
        with pytest.raises(ApiError) as caught:
            AgentClient(api, None, timeout=5).request(method, path, body)
        assert caught.value.status == 401, (method, path)
    bad = AgentClient(api, lab.lab.robots[1].token, timeout=5)
    with pytest.raises(ApiError) as caught:
        bad.post("/v1/keys/fleet", {"op": "add", "key": "abcd"})
    assert caught.value.status == 400
    assert 'field "key"' in str(caught.value)


def test_key_help_names_every_action() -> None:
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", "key", "--help"],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0
    for word in ("list", "add", "primary", "retire", "rotate"):
        assert word in done.stdout
