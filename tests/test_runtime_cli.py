"""The instance commands' pure parts: the minimal system file, the table, log tail/follow, specs
built from flags."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.cli import build_parser
from sdrpeer.cli_format import format_instances
from sdrpeer.errors import ConfigError
from sdrpeer.runtime.commands import instance_doc
from sdrpeer.runtime.logfile import Follower, tail
from sdrpeer.runtime.simple_system import load_simple_system

GOOD = """\
components:
  - name: Cam
    target: pkg.cam:Camera
    params: {fps: 10}
  - {name: View, target: pkg.view:Viewer, launcher: python}
connections:
  - {from: Cam.image, to: View.image, policy: {buffer: 4, full: drop}}
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "system.yaml"
    path.write_text(text)
    return path


def test_simple_system(tmp_path):
    cam, view = load_simple_system(write(tmp_path, GOOD))
    assert (cam.name, cam.component, cam.params_map()) == ("Cam", "Camera", {"fps": 10})
    assert view.connections == ()
    (conn,) = cam.connections
    assert (conn.id, conn.out_port, conn.to_instance, conn.in_port) == (
        "Cam.image->View.image",
        "image",
        "View",
        "image",
    )
    assert conn.policy_map() == {"buffer": 4, "full": "drop"}


@pytest.mark.parametrize(
    ("text", "where"),
    [
        ("components: [{name: A}]\n", ":1: field 'components[0].target': missing"),
        ("components:\n  - {name: A, target: nocolon}\n", ":2: field 'components[0].target'"),
        ("components:\n  - {name: A, target: m:C, x: 1}\n", ":2: field 'components[0].x'"),
        (
            "components:\n  - {name: A, target: m:C}\n  - {name: A, target: m:C}\n",
            ":3: field 'components[1].name': 'A' given twice",
        ),
        (
            "components:\n  - {name: A, target: m:C}\nconnections:\n  - {from: A, to: A.i}\n",
            ":4: field 'connections[0].from': expected Component.port",
        ),
        (
            "components:\n  - {name: A, target: m:C}\nconnections:\n  - {from: A.o, to: B.i}\n",
            ":4: field 'connections[0].to': no component 'B'",
        ),
        (
            "components:\n  - {name: A, target: m:C}\nconnections:\n"
            "  - from: A.o\n    to: A.i\n    policy: {buffer: 0}\n",
            ":6: field 'connections[0].policy.buffer'",
        ),
        ("components: [\n", ": not valid YAML"),
    ],
)
def test_simple_system_errors_say_where(tmp_path, text, where):
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_simple_system(path)
    assert str(info.value).startswith(str(path))
    assert where in str(info.value)


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
