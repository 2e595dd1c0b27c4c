"""The `sdrpeer` command without agents: flags <-> fields, endpoint lookup, client errors."""

from __future__ import annotations

import argparse
import json
import threading
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from sdrpeer.cli.agent import agent_flag_values
from sdrpeer.cli.common import parse_assignment
from sdrpeer.cli.main import build_parser, main
from sdrpeer.client import AgentClient, resolve_endpoint
from sdrpeer.config import FIELDS, flag_name
from sdrpeer.errors import ApiError, ConfigError
from sdrpeer.lab.files import Lab, LabRobot, write_lab


def test_every_config_field_has_its_flag() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if isinstance(a, argparse._SubParsersAction))
    agent = sub.choices["agent"]
    flags = {opt for action in agent._actions for opt in action.option_strings}
    assert {flag_name(f) for f in FIELDS} <= flags


def test_agent_flags_parse_onto_fields(tmp_path: Path) -> None:
    argv = "agent --name r1 --join a:1 --join b:2 --insecure --priority 3 --metrics-interval 0.5"
    args = build_parser().parse_args([*argv.split(), "--key-file", str(tmp_path / "k")])
    values = agent_flag_values(args)
    assert values["join"] == ["a:1", "b:2"]
    assert values["insecure"] is True
    assert values["priority"] == 3
    assert values["metrics_interval"] == 0.5
    assert values["key_file"] == tmp_path / "k"
    assert values["bind"] is None  # not given: the file or the default decides


@pytest.mark.parametrize(
    ("value", "message"),
    [
        ("2147483648", "2147483648 is out of range (-2147483648 to 2147483647)"),
        ("high", "expected an integer, got 'high'"),
    ],
)
def test_agent_priority_flag_is_refused_outside_the_records_range(
    value: str, message: str, capsys: pytest.CaptureFixture[str]
) -> None:
    with pytest.raises(SystemExit) as info:
        build_parser().parse_args(["agent", "--name", "r1", "--priority", value])
    assert info.value.code == 2
    assert message in capsys.readouterr().err


def test_agent_config_error_exits_2(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["agent", "--name", "robot-1"]) == 2
    assert capsys.readouterr().err == (
        "error: no cluster key: pass --key-file FILE, "
        "or --insecure to run unauthenticated (not for real robots)\n"
    )


def test_agent_config_file_error_names_file_and_line(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    config = tmp_path / "agent.yaml"
    config.write_text("name: robot-1\nprioriti: 2\n")
    assert main(["agent", "--config", str(config)]) == 2
    assert capsys.readouterr().err.startswith(f"error: {config}:2: unknown field 'prioriti'")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("battery=30%", ("battery", "30%")),
        ("rssi=-55dBm", ("rssi", "-55dBm")),
        ("rssi=-55", ("rssi", -55)),
        ("drain=0.5", ("drain", 0.5)),
        ("pos=3,4.5", ("pos", [3, 4.5])),
    ],
)
def test_parse_assignment(text: str, expected: tuple[str, object]) -> None:
    assert parse_assignment(text) == expected


@pytest.mark.parametrize("text", ["battery", "=3", "battery="])
def test_parse_assignment_errors(text: str) -> None:
    with pytest.raises(ConfigError, match="expected key=value"):
        parse_assignment(text)


def write_two_robot_lab(lab_dir: Path) -> None:
    robots = [
        LabRobot("robot-1", "d1", "l1", "tok-1", pid=1, api="http://127.0.0.1:1001"),
        LabRobot("robot-2", "d2", "l2", "tok-2", pid=2, api="http://127.0.0.1:1002"),
    ]
    write_lab(lab_dir, Lab(robots=robots, key_file="k"))


def test_resolve_endpoint_order(tmp_path: Path) -> None:
    write_two_robot_lab(tmp_path)
    lab = resolve_endpoint(None, None, tmp_path, {})
    assert (lab.api, lab.token) == ("http://127.0.0.1:1001", "tok-1")
    env = {"SDRPEER_API": "127.0.0.1:1002/", "SDRPEER_TOKEN": "env-tok"}
    from_env = resolve_endpoint(None, None, tmp_path, env)
    assert (from_env.api, from_env.token, from_env.source) == (
        "http://127.0.0.1:1002",
        "env-tok",
        "$SDRPEER_API",
    )
    flag = resolve_endpoint("http://127.0.0.1:1002", None, tmp_path, {"SDRPEER_API": "x:1"})
    assert (flag.api, flag.token) == ("http://127.0.0.1:1002", "tok-2")  # token from the lab
    explicit = resolve_endpoint("http://127.0.0.1:1002", "mine", tmp_path, {})
    assert explicit.token == "mine"


def test_resolve_endpoint_without_anything(tmp_path: Path) -> None:
    with pytest.raises(ApiError, match="no agent to talk to: pass --api URL, set SDRPEER_API"):
        resolve_endpoint(None, None, tmp_path, {})


class _Stub(BaseHTTPRequestHandler):
    def do_GET(self) -> None:
        status: int = 404
        body: object = {}
        if self.path == "/v1/members":
            status, body = 200, [{"name": "robot-1"}]
        elif self.path == "/v1/boom":
            status, body = 400, {"error": "since must be an integer"}
        raw = json.dumps(body).encode()
        self.send_response(status)
        self.send_header("Content-Type", "application/json")
        self.send_header("Content-Length", str(len(raw)))
        self.end_headers()
        self.wfile.write(raw)

    def log_message(self, format: str, *args: object) -> None:
        pass


@pytest.fixture
def stub_api() -> Iterator[str]:
    server = ThreadingHTTPServer(("127.0.0.1", 0), _Stub)
    thread = threading.Thread(target=server.serve_forever, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_address[1]}"
    server.shutdown()
    server.server_close()
    thread.join()


def test_client_answers_and_errors(stub_api: str) -> None:
    client = AgentClient(stub_api)
    assert client.members() == [{"name": "robot-1"}]
    with pytest.raises(ApiError, match=r"answered 400: since must be an integer$"):
        client.get("/v1/boom")


def test_client_unreachable_message() -> None:
    with pytest.raises(ApiError) as info:
        AgentClient("http://127.0.0.1:1").members()
    assert str(info.value) == (
        "cannot reach agent at http://127.0.0.1:1: connection refused; "
        "is it running? (sdrpeer lab up)"
    )


def test_members_command_prints_table_and_json(
    stub_api: str, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["members", "--api", stub_api, "--lab-dir", str(tmp_path)]) == 0
    assert capsys.readouterr().out.splitlines()[1].startswith("robot-1  -")
    assert main(["members", "--json", "--api", stub_api, "--lab-dir", str(tmp_path)]) == 0
    assert json.loads(capsys.readouterr().out) == [{"name": "robot-1"}]


def test_unreachable_agent_exits_1(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["members", "--api", "127.0.0.1:1", "--lab-dir", str(tmp_path)]) == 1
    assert "connection refused; is it running?" in capsys.readouterr().err
