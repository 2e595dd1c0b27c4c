"""The instance commands' pure parts: `run` on one robot, the table, log tail/follow, specs
built from flags."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.cli.format import format_instances
from sdrpeer.cli.instances import instance_doc
from sdrpeer.cli.main import build_parser
from sdrpeer.deploy.one_robot import load_on_one_robot
from sdrpeer.errors import ConfigError
from sdrpeer.runtime.logfile import Follower, tail

GOOD = """\
name: two
components:
  - name: Pub
    target: tests.components_fixture:Counter
    params: {rate: 10}
  - {name: Rec, target: "tests.components_fixture:Recorder", launcher: python}
connections:
  - {from: Pub.out, to: Rec.inp, policy: {buffer: 4, full: drop}}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "system.yaml"
    path.write_text(text)
    return path


def test_run_places_a_whole_system_on_one_robot(tmp_path):
    pub, rec = load_on_one_robot(write(tmp_path, GOOD), "robot-1")
    assert (pub.name, pub.component, pub.params_map()) == ("Pub", "Pub", {"rate": 10.0})
    assert rec.connections == ()
    (conn,) = pub.connections
    assert (conn.id, conn.out_port, conn.to_instance, conn.in_port, conn.to_addr) == (
        "Pub.out->Rec.inp",
        "out",
        "Rec",
        "inp",
        None,
    )
    assert conn.policy_map() == {"buffer": 4, "full": "drop"}


def test_paper_one_robot_file_loads():
    specs = load_on_one_robot(Path(__file__).parent.parent / "examples/paper/one-robot.yaml", "r")
    assert len(specs) == 5
    assert sum(len(s.connections) for s in specs) == 4


def test_run_refuses_a_broken_file_naming_the_line(tmp_path):
    path = write(tmp_path, GOOD.replace("Rec.inp", "Rec.nope"))
    with pytest.raises(ConfigError) as info:
        load_on_one_robot(path, "robot-1")
    assert f"{path}:8" in str(info.value)
    assert "nope" in str(info.value)


def test_format_instances():
    rows: list[dict[str, Any]] = [
        {
            "name": "Cam1",
            "component": "CameraRTC",
            "state": "ACTIVE",
            "role": "active",
            "pid": 4242,
            "cpu_pct": 12.3,
            "rss": 52_000_000,
            "restarts": 1,
            "since": 1000.0,
        },
        {"name": "View1", "component": "Viewer", "state": "STOPPED", "role": "standby"},
    ]
    assert format_instances(rows, now=1075.0).splitlines() == [
        "NAME   COMPONENT  STATE    ROLE     PID   CPU  RSS     RESTARTS  SINCE",
        "Cam1   CameraRTC  ACTIVE   active   4242  12%  52.0MB  1         1m15s",
        "View1  Viewer     STOPPED  standby  -     -    -       -         -",
    ]
    assert "\x1b[32mACTIVE" in format_instances(rows, now=1075.0, color=True)


def test_log_tail_and_follow(tmp_path):
    path = tmp_path / "x.log"
    assert tail(path, 5) == b""
    path.write_bytes(b"".join(b"line %d\n" % i for i in range(5000)))
    assert tail(path, 2) == b"line 4998\nline 4999\n"
    assert tail(path, 0) == b""
    assert tail(path, 3, max_bytes=12) == b"8\nline 4999\n"  # the last 12 bytes
    follower = Follower(path)
    assert follower.read_new() == b""
    with path.open("ab") as f:
        f.write(b"new\n")
    assert follower.read_new() == b"new\n"
    path.write_bytes(b"rotated\n")  # replaced or truncated: start over
    assert follower.read_new() == b"rotated\n"


def parse(*argv: str) -> argparse.Namespace:
    return build_parser().parse_args(["start-instance", *argv])


def test_start_instance_flags_make_a_spec():
    args = parse("--name", "C1", "--target", "pkg.m:Cam", "--param", "fps=10", "--inactive")
    assert instance_doc(args) == {
        "name": "C1",
        "launcher": "python",
        "target": "pkg.m:Cam",
        "params": {"fps": 10},
        "desired": "inactive",
    }
    args = parse("--name", "X", "--launcher", "exec", "--target", "/bin/x --fast")
    assert instance_doc(args)["target"] == ["/bin/x", "--fast"]
    with pytest.raises(ConfigError, match=r"instance\.target"):
        instance_doc(parse("--name", "C1", "--target", "nocolon"))


def test_parser_knows_the_instance_commands():
    p = build_parser()
    assert p.parse_args(["logs", "Cam1", "-f", "--tail", "5"]).follow
    assert p.parse_args(["instances", "--json"]).json
    assert p.parse_args(["run", "s.yaml", "--robot", "robot-1"]).robot == "robot-1"
