"""AgentConfig: file loading with line numbers, flags over file, every validation message."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest

from sdrpeer.config import (
    MAX_NAME,
    NO_KEY_MESSAGE,
    AgentConfig,
    build_config,
    load_agent_config,
    parse_hostport,
)
from sdrpeer.errors import ConfigError
from sdrpeer.gossip import wire
from sdrpeer.launch.policy import LaunchPolicy


def write(tmp_path: Path, text: str, name: str = "agent.yaml") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


@pytest.fixture
def key(tmp_path: Path) -> Path:
    path = tmp_path / "cluster.key"
    path.write_text("00" * 32)
    return path


def test_fields_are_the_documented_set() -> None:
    fields = {f.name for f in dataclasses.fields(AgentConfig)}
    assert fields == {
        "name",
        "bind",
        "join",
        "api",
        "robot_file",
        "scenario",
        "scenario_start",
        "key_file",
        "insecure",
        "allow_launchers",
        "allow_targets",
        "token_file",
        "preset",
        "data_dir",
        "metrics_interval",
        "priority",
        "preempt",
        "log_level",
        "log_format",
        "discover",
        "ros2_domain",
    }


def test_defaults_and_data_dir_expansion() -> None:
    config = build_config(None, {"name": "robot-1", "insecure": True})
    assert config.bind == "127.0.0.1:7946"
    assert config.api == "127.0.0.1:8080"
    assert config.join == ()
    assert config.preset == "lan"
    assert config.data_dir == Path.home() / ".local/share/sdrpeer/robot-1"
    assert config.token_file is None
    assert config.launch_policy == LaunchPolicy(("python",), ("*",))  # exec and script off


def test_file_values_are_typed_and_paths_file_relative(tmp_path: Path) -> None:
    (tmp_path / "cluster.key").write_text("00" * 32)
    path = write(
        tmp_path,
        "name: robot-2\n"
        "key-file: cluster.key\n"
        "join: [10.0.0.1:7946, 10.0.0.2:7946]\n"
        "metrics_interval: 2\n"
        "priority: 5\n"
        "insecure: false\n",
    )
    values = load_agent_config(path)
    assert values == {
        "name": "robot-2",
        "key_file": tmp_path / "cluster.key",
        "join": ("10.0.0.1:7946", "10.0.0.2:7946"),
        "metrics_interval": 2.0,
        "priority": 5,
        "insecure": False,
    }
    assert values.origin["priority"] == f"{path}:5"
    config = build_config(values, {})
    assert config.key_file == tmp_path / "cluster.key"
    assert config.join == ("10.0.0.1:7946", "10.0.0.2:7946")


def test_launch_settings_from_a_file_and_flags(tmp_path: Path, key: Path) -> None:
    path = write(
        tmp_path,
        "name: r\nallow-launchers: [exec, script]\nallow_targets: [components.*, mylab.*]\n",
    )
    config = build_config(load_agent_config(path), {"key_file": key})
    assert config.launch_policy == LaunchPolicy(
        ("python", "exec", "script"), ("components.*", "mylab.*")
    )
    flags = {"key_file": key, "allow_launchers": ["exec"], "allow_targets": None}
    config = build_config(load_agent_config(path), flags)
    assert config.launch_policy.launchers == ("python", "exec")  # the flag wins, the file's
    assert config.launch_policy.targets == ("components.*", "mylab.*")  # targets stay
    with pytest.raises(ConfigError, match=r":2: allow-launchers: expected a list of names"):
        load_agent_config(write(tmp_path, "name: r\nallow-launchers: [exec, 3]\n"))


def test_flags_override_file(tmp_path: Path, key: Path) -> None:
    path = write(tmp_path, "name: from-file\nbind: 0.0.0.0:7000\npriority: 1\njoin: [a:1]\n")
    flags = {"name": "from-flag", "bind": None, "priority": 9, "join": ["b:2"], "key_file": key}
    config = build_config(load_agent_config(path), flags)
    assert config.name == "from-flag"
    assert config.bind == "0.0.0.0:7000"  # flag not given (None): file value stays
    assert config.priority == 9
    assert config.join == ("b:2",)


def test_empty_file_is_no_values(tmp_path: Path) -> None:
    assert load_agent_config(write(tmp_path, "# nothing\n")) == {}


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("name: r\nbogus: 1\n", ":2: unknown field 'bogus' (known: name, bind, join,"),
        ("name: r\npriority: high\n", ":2: priority: expected an integer, got 'high'"),
        (
            "name: r\npriority: -99999999999999999999\n",
            ":2: priority: -99999999999999999999 is out of range (-2147483648 to 2147483647)",
        ),
        ("name: r\n\ninsecure: yes please\n", ":3: insecure: expected true or false"),
        ("name: 5\n", ":1: name: expected a string, got 5"),
        ("join: [1, 2]\n", ":1: join: expected a list of HOST:PORT strings"),
        ("metrics-interval: true\n", ":1: metrics-interval: expected a number, got True"),
        ("name: a\nname: b\n", ":2: name: given twice (first at "),
        ("name: a\nkey_file: x\nkey-file: y\n", ":3: key-file: given twice"),
        ("- a\n- b\n", ":1: an agent config is a mapping of field: value"),
        ("name: [a\n", ": not valid YAML: "),
    ],
)
def test_file_errors_name_file_line_and_field(tmp_path: Path, text: str, message: str) -> None:
    path = write(tmp_path, text)
    with pytest.raises(ConfigError) as info:
        load_agent_config(path)
    assert str(info.value).startswith(str(path))
    assert message in str(info.value)


def test_missing_file(tmp_path: Path) -> None:
    with pytest.raises(ConfigError, match=r"nope\.yaml: cannot read"):
        load_agent_config(tmp_path / "nope.yaml")


@pytest.mark.parametrize(
    ("flags", "message"),
    [
        ({}, "no robot name: pass --name NAME (or name: in the config file)"),
        ({"name": "robot 1"}, "--name: name: 'robot 1' may only contain letters, digits"),
        (  # the gossip wire carries at most 255 characters: peers would refuse every datagram
            {"name": "r" * 256},
            f"--name: name: '{'r' * 60}'... (256 characters) is longer than 255 characters",
        ),
        ({"bind": "localhost"}, "--bind: bind: 'localhost' is not HOST:PORT (no port;"),
        ({"bind": "h:99999"}, "--bind: bind: 'h:99999': port must be in 0..65535"),
        ({"api": ":80"}, "--api: api: ':80' is not HOST:PORT (bad host ''"),
        ({"api": "h:http"}, "--api: api: 'h:http' is not HOST:PORT (port 'http' is not a number)"),
        ({"join": ["h:0"]}, "--join: join: 'h:0': port must be in 1..65535"),
        ({"preset": "wan"}, "--preset: preset: unknown preset 'wan' (known: lan, fast_test, lab)"),
        ({"log_level": "loud"}, "--log-level: log-level: must be one of debug, info, warning"),
        ({"log_format": "xml"}, "--log-format: log-format: must be one of text, json"),
        ({"metrics_interval": 0.0}, "--metrics-interval: metrics-interval: must be > 0 seconds"),
        (
            {"allow_launchers": ["exec", "rsh"]},
            "--allow-launchers: allow-launchers: unknown launcher 'rsh' (known: composite, exec,",
        ),
        ({"allow_targets": [" "]}, "--allow-targets: allow-targets: a pattern must not be empty"),
        ({"robot_file": Path("/no/such.yaml")}, "--robot-file: robot-file: /no/such.yaml does"),
        ({"token_file": Path("/no/token")}, "--token-file: token-file: /no/token does not exist"),
    ],
)
def test_flag_validation_messages(flags: dict[str, object], message: str) -> None:
    values = {"name": "robot-1", "insecure": True} | flags
    if flags == {}:
        values = {"insecure": True}
    with pytest.raises(ConfigError) as info:
        build_config(None, values)
    assert str(info.value).startswith(message)


def test_file_validation_error_names_file_and_line(tmp_path: Path) -> None:
    path = write(tmp_path, "name: robot-1\ninsecure: true\n\nbind: nowhere\n")
    with pytest.raises(ConfigError) as info:
        build_config(load_agent_config(path), {})
    assert str(info.value) == (
        f"{path}:4: bind: 'nowhere' is not HOST:PORT (no port; e.g. 127.0.0.1:7946)"
    )


def test_an_unknown_preset_in_a_file_names_file_line_and_field(tmp_path: Path) -> None:
    path = write(tmp_path, "name: robot-1\ninsecure: true\npreset: wan\n")
    with pytest.raises(ConfigError) as info:
        build_config(load_agent_config(path), {})
    assert str(info.value) == f"{path}:3: preset: unknown preset 'wan' (known: lan, fast_test, lab)"


def test_refuses_without_key_unless_insecure(key: Path) -> None:
    with pytest.raises(ConfigError) as info:
        build_config(None, {"name": "robot-1"})
    assert str(info.value) == NO_KEY_MESSAGE
    assert "--key-file FILE" in NO_KEY_MESSAGE
    assert "--insecure" in NO_KEY_MESSAGE
    assert build_config(None, {"name": "robot-1", "key_file": key}).key_file == key
    assert build_config(None, {"name": "robot-1", "insecure": True}).insecure is True


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("127.0.0.1:7946", ("127.0.0.1", 7946)),
        ("robot-1.local:0", ("robot-1.local", 0)),
        ("[::1]:8080", ("::1", 8080)),
    ],
)
def test_parse_hostport(text: str, expected: tuple[str, int]) -> None:
    assert parse_hostport(text) == expected


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("", "is not HOST:PORT (empty)"),
        ("::1:80", "write an IPv6 address in brackets"),
        ("[::1]80", "is not [IPV6]:PORT"),
        ("h:-1", "port '-1' is not a number"),
    ],
)
def test_parse_hostport_errors(text: str, message: str) -> None:
    with pytest.raises(ValueError, match=re.escape(message)):
        parse_hostport(text)


def test_a_robot_name_may_be_as_long_as_the_gossip_wire_carries() -> None:
    assert MAX_NAME == wire.MAX_NAME
    assert build_config(None, {"name": "r" * MAX_NAME, "insecure": True}).name == "r" * MAX_NAME
