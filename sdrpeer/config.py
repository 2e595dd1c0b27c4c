"""Agent configuration: one frozen dataclass, a YAML file loader and the flags-over-file merge.

Every `sdrpeer agent` flag maps onto one `AgentConfig` field (`--key-file` -> `key_file`); an
agent config file uses the same names (dashes or underscores). `build_config` merges the two
(flags win) and validates; every error names where the bad value came from (`agent.yaml:3` or
`--bind`) and the field.
"""

from __future__ import annotations

import dataclasses
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from sdrpeer.errors import ConfigError, shown
from sdrpeer.launch.policy import DEFAULT_TARGETS, LaunchPolicy
from sdrpeer.record.limits import check_int

NAME_RE = re.compile(r"[A-Za-z0-9_.-]+")
MAX_NAME = 255
"""A robot name's most characters: the gossip wire carries no longer one (`sdrpeer.gossip.wire.
MAX_NAME`, held equal by tests/test_config.py): an agent with a longer name would be refused by
every peer."""
PRESETS_SAID = {
    "lan": "robots on one Wi-Fi network: sub-2-second failure detection, tolerant of 30 % loss",
    "fast_test": "loopback tests: fast timers, short reaping; a busy machine makes it flap",
    "lab": "many agents sharing a few busy cores (sdrpeer lab up): slower, no false deaths",
}
"""What each preset is for, in one line (the `--help` of `sdrpeer agent` and `lab up`, without
loading the tree; a test holds each to the first line of its `sdrpeer.agent.tuning` function)."""
PRESET_NAMES = tuple(PRESETS_SAID)
"""The presets `--preset` takes: each names one tree of every timer and size of the agent and its
parts (`sdrpeer.agent.tuning.PRESETS`, which builds one for each of these names)."""
AGENT_PRESET = "lan"
"""The preset an agent runs with unless its flags or file name another (`AgentConfig.preset`)."""
LAB_PRESET = "lab"
"""The preset `sdrpeer lab up` gives its agents unless told otherwise."""


def presets_epilog(default: str) -> str:
    """The presets, one line each, for a parser's epilog (RawDescriptionHelpFormatter)."""
    lines = [f"presets (--preset; default {default}):"]
    lines += [f"  {name:<10} {said}" for name, said in PRESETS_SAID.items()]
    return "\n".join(lines)


LOG_LEVELS = ("debug", "info", "warning", "error")
LOG_FORMATS = ("text", "json")
NO_KEY_MESSAGE = (
    "no cluster key: pass --key-file FILE, "
    "or --insecure to run unauthenticated (not for real robots)"
)


@dataclass(frozen=True, slots=True)
class AgentConfig:
    """Everything one agent needs to start; build it with `build_config`."""

    name: str
    """This robot's name, unique in the cluster ([A-Za-z0-9_.-]+)."""
    bind: str = "127.0.0.1:7946"
    """UDP host:port for gossip; port 0 picks a free port (the agent reports it in agent.json)."""
    join: tuple[str, ...] = ()
    """host:port of members to contact at start; empty = start a new cluster."""
    api: str = "127.0.0.1:8080"
    """HTTP API host:port; port 0 picks a free port (the agent reports it in agent.json)."""
    robot_file: Path | None = None
    """YAML file with this virtual robot's hardware facts; None = read the real sources."""
    scenario: Path | None = None
    """YAML scenario that changes the virtual robot's facts over time."""
    scenario_start: float | None = None
    """Unix time of the scenario's time 0 (None: this agent's start). The lab gives every agent
    its own start time, so the agents' steps and the lab's (deaths, partitions) share one clock
    and a restarted agent goes on with the scenario where it is instead of starting it over."""
    key_file: Path | None = None
    """Cluster key (hex) used to sign every datagram; required unless `insecure`."""
    insecure: bool = False
    """Run without a cluster key (unauthenticated; not for real robots)."""
    allow_launchers: tuple[str, ...] = ()
    """Launchers this robot's hosts may use besides python (`sdrpeer.launch.policy`): exec and
    script run anything the agent's user can, so they are off unless named here."""
    allow_targets: tuple[str, ...] = DEFAULT_TARGETS
    """Shell patterns a python target (package.module:Class) must match one of."""
    token_file: Path | None = None
    """API bearer token file; None = the agent generates one into data_dir/token (mode 0600)."""
    preset: str = AGENT_PRESET
    """The preset of every timer and size of the agent and its parts (`sdrpeer.agent.tuning`):
    lan (robots on one Wi-Fi network), lab (many agents on one busy machine: `sdrpeer lab up`'s
    default) or fast_test (loopback tests); `PRESETS_SAID` says each in one line."""
    data_dir: Path = Path("~/.local/share/sdrpeer/{name}")
    """Directory for the token, agent.json and logs; `~` and `{name}` are expanded."""
    metrics_interval: float = 1.0
    """Seconds between two samples of this robot's metrics."""
    priority: int = 0
    """Election priority: higher wins among equally healthy robots; at start (a robot's first
    seconds) a higher priority also takes the role from an allocator that claimed first
    (`ElectionConfig.priority_window`)."""
    preempt: bool = False
    """Take the allocator role from any healthy allocator ranked below this robot, at any time
    (not only at start); the system file's `allocation.preempt` does it for the whole fleet."""
    log_level: str = "info"
    """debug, info, warning or error."""
    log_format: str = "text"
    """text (human) or json (one object per line)."""
    ros2_domain: int | None = None
    """The fleet's ROS 2 domain (ROS_DOMAIN_ID, 0..101) for hosts of the `ros2` launcher
    (sdrpeer.ros2.env); every robot of a fleet must give the same. None: the agent's own
    ROS_DOMAIN_ID if set, else `default_domain("sdrpeer")` (not 0, so that stock ROS 2 nodes on
    a robot do not join the fleet's graph)."""
    discover: bool = False
    """Find the fleet on the local network by mDNS/DNS-SD (sdrpeer.agent.discovery): advertise
    this robot's gossip address and join the robots found, no `join` needed. Off by default: it
    announces the agent to the whole network segment. Discovery finds addresses only; the
    cluster key still authenticates everything."""

    @property
    def launch_policy(self) -> LaunchPolicy:
        """What this agent's configuration lets its hosts run (the agent offers less when a
        launcher cannot run here: `sdrpeer.launch.launchers.offered`)."""
        return LaunchPolicy(("python", *self.allow_launchers), self.allow_targets)

    def __post_init__(self) -> None:
        expanded = Path(str(self.data_dir).replace("{name}", self.name)).expanduser()
        object.__setattr__(self, "data_dir", expanded)


FIELDS: dict[str, dataclasses.Field[Any]] = {f.name: f for f in dataclasses.fields(AgentConfig)}


class ConfigValues(dict[str, Any]):
    """Field values plus where each came from (`origin[field]` = "agent.yaml:3" or "--bind")."""

    def __init__(self) -> None:
        super().__init__()
        self.origin: dict[str, str] = {}


def flag_name(field: str) -> str:
    """The command-line flag for a config field: key_file -> --key-file."""
    return "--" + field.replace("_", "-")


def parse_hostport(text: str, *, allow_port_zero: bool = True) -> tuple[str, int]:
    """Split "host:port" (or "[v6addr]:port") into (host, port); ValueError says what is wrong."""
    if not isinstance(text, str) or not text.strip():
        raise ValueError(f"{text!r} is not HOST:PORT (empty)")
    if text.startswith("["):
        end = text.find("]")
        if end < 0 or text[end + 1 : end + 2] != ":":
            raise ValueError(f"{text!r} is not [IPV6]:PORT")
        host, port_text = text[1:end], text[end + 2 :]
    else:
        host, sep, port_text = text.rpartition(":")
        if not sep:
            raise ValueError(f"{text!r} is not HOST:PORT (no port; e.g. 127.0.0.1:7946)")
        if ":" in host:
            raise ValueError(f"{text!r}: write an IPv6 address in brackets, e.g. [::1]:7946")
    if not host or any(c.isspace() for c in host):
        raise ValueError(f"{text!r} is not HOST:PORT (bad host {host!r})")
    if not port_text.isdigit():
        raise ValueError(f"{text!r} is not HOST:PORT (port {port_text!r} is not a number)")
    port = int(port_text)
    low = 0 if allow_port_zero else 1
    if not low <= port <= 65535:
        raise ValueError(f"{text!r}: port must be in {low}..65535")
    return host, port


# --- the YAML file ---------------------------------------------------------------------------


def _as_str(value: Any) -> str:
    if not isinstance(value, str):
        raise TypeError("expected a string")
    return value


def _as_path(value: Any) -> Path:
    return Path(_as_str(value)).expanduser()


def _as_bool(value: Any) -> bool:
    if not isinstance(value, bool):
        raise TypeError("expected true or false")
    return value


def _as_int(value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int):
        raise TypeError("expected an integer")
    return value


def _as_priority(value: Any) -> int:
    return check_int("priority", _as_int(value))


def _as_domain(value: Any) -> int:
    n = _as_int(value)
    if not 0 <= n <= 101:
        raise ValueError(f"a ROS 2 domain is 0..101, got {n}")
    return n


def _as_float(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise TypeError("expected a number")
    return float(value)


def _as_str_tuple(value: Any) -> tuple[str, ...]:
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, list) or not all(isinstance(v, str) for v in value):
        raise TypeError("expected a list of HOST:PORT strings")
    return tuple(value)


def _as_names(value: Any) -> tuple[str, ...]:
    if isinstance(value, str):
        return (value,)
    if not isinstance(value, list) or not all(isinstance(v, str) and v for v in value):
        raise TypeError("expected a list of names")
    return tuple(value)


_TUPLE_FIELDS = ("join", "allow_launchers", "allow_targets")


_CONVERT: dict[str, Callable[[Any], Any]] = {
    "name": _as_str,
    "bind": _as_str,
    "join": _as_str_tuple,
    "api": _as_str,
    "robot_file": _as_path,
    "scenario": _as_path,
    "scenario_start": _as_float,
    "key_file": _as_path,
    "insecure": _as_bool,
    "allow_launchers": _as_names,
    "allow_targets": _as_names,
    "token_file": _as_path,
    "preset": _as_str,
    "data_dir": _as_path,
    "metrics_interval": _as_float,
    "priority": _as_priority,
    "preempt": _as_bool,
    "log_level": _as_str,
    "log_format": _as_str,
    "discover": _as_bool,
    "ros2_domain": _as_domain,
}
_PATH_FIELDS = ("robot_file", "scenario", "key_file", "token_file", "data_dir")


def load_agent_config(path: Path | str) -> ConfigValues:
    """Read an agent config file into typed field values; relative paths are file-relative."""
    import yaml  # noqa: PLC0415 - only --config FILE needs it (keeps the agent's start light)

    from sdrpeer.yamlfile import compose, read_text, yaml_problem  # noqa: PLC0415

    path = Path(path)
    loader, root = compose(read_text(path), str(path))
    try:
        values = ConfigValues()
        if root is None:
            return values
        if not isinstance(root, yaml.MappingNode):
            line = root.start_mark.line + 1
            raise ConfigError(f"{path}:{line}: an agent config is a mapping of field: value")
        for key_node, value_node in root.value:
            where = f"{path}:{key_node.start_mark.line + 1}"
            key = loader.construct_object(key_node, deep=True)
            field = str(key).replace("-", "_")
            if field not in _CONVERT:
                known = ", ".join(f.replace("_", "-") for f in _CONVERT)
                raise ConfigError(f"{where}: unknown field {key!r} (known: {known})")
            if field in values:
                raise ConfigError(f"{where}: {key}: given twice (first at {values.origin[field]})")
            raw = loader.construct_object(value_node, deep=True)
            try:
                value = _CONVERT[field](raw)
            except TypeError as exc:
                raise ConfigError(f"{where}: {key}: {exc}, got {raw!r}") from None
            except ValueError as exc:  # a range: the message quotes the value
                raise ConfigError(f"{where}: {key}: {exc}") from None
            if field in _PATH_FIELDS and not value.is_absolute():
                value = path.parent / value
            values[field] = value
            values.origin[field] = where
        return values
    except yaml.MarkedYAMLError as exc:  # constructing a value (an unhashable key...)
        raise ConfigError(yaml_problem(str(path), exc)) from None
    finally:
        loader.dispose()


# --- merge and validate ----------------------------------------------------------------------


def build_config(
    file_values: Mapping[str, Any] | None, flag_values: Mapping[str, Any]
) -> AgentConfig:
    """Merge file values and flags (flags win, None = not given) and validate the result."""
    merged: dict[str, Any] = {}
    origin: dict[str, str] = {}
    file_origin = getattr(file_values, "origin", {})
    for source, is_flag in ((file_values or {}, False), (flag_values, True)):
        for field, value in source.items():
            if field not in FIELDS:
                raise ConfigError(f"unknown agent config field {field!r}")
            if value is None:
                continue
            merged[field] = tuple(value) if field in _TUPLE_FIELDS else value
            origin[field] = flag_name(field) if is_flag else file_origin.get(field, "config file")
    _validate(merged, origin)
    return AgentConfig(**merged)


def _validate(values: dict[str, Any], origin: dict[str, str]) -> None:
    def fail(field: str, message: str) -> ConfigError:
        return ConfigError(f"{origin[field]}: {field.replace('_', '-')}: {message}")

    name = values.get("name")
    if not name:
        raise ConfigError("no robot name: pass --name NAME (or name: in the config file)")
    if not NAME_RE.fullmatch(name):
        raise fail("name", f"{shown(name)} may only contain letters, digits, '_', '.' and '-'")
    if len(name) > MAX_NAME:
        raise fail("name", f"{shown(name)} is longer than {MAX_NAME} characters")
    for field in ("bind", "api"):
        if field in values:
            try:
                parse_hostport(values[field])
            except ValueError as exc:
                raise fail(field, str(exc)) from None
    for peer in values.get("join", ()):
        try:
            parse_hostport(peer, allow_port_zero=False)
        except ValueError as exc:
            raise fail("join", str(exc)) from None
    if "allow_launchers" in values:
        from sdrpeer.launch.launchers import known_launchers  # noqa: PLC0415 - plugins: entry points

        known = known_launchers()
        for name in values["allow_launchers"]:
            if name not in known:
                raise fail(
                    "allow_launchers", f"unknown launcher {name!r} (known: {', '.join(known)})"
                )
    for pattern in values.get("allow_targets", ()):
        if not pattern.strip():
            raise fail("allow_targets", "a pattern must not be empty")
    if "preset" in values and values["preset"] not in PRESET_NAMES:
        names = ", ".join(PRESET_NAMES)
        raise fail("preset", f"unknown preset {values['preset']!r} (known: {names})")
    if "log_level" in values and values["log_level"] not in LOG_LEVELS:
        raise fail("log_level", f"must be one of {', '.join(LOG_LEVELS)}")
    if "log_format" in values and values["log_format"] not in LOG_FORMATS:
        raise fail("log_format", f"must be one of {', '.join(LOG_FORMATS)}")
    if "metrics_interval" in values and not values["metrics_interval"] > 0:
        raise fail("metrics_interval", "must be > 0 seconds")
    for field in ("robot_file", "scenario", "key_file", "token_file"):
        if field in values and not Path(values[field]).expanduser().is_file():
            raise fail(field, f"{values[field]} does not exist or is not a file")
    if "key_file" not in values and not values.get("insecure", False):
        raise ConfigError(NO_KEY_MESSAGE)
