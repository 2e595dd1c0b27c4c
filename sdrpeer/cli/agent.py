"""`sdrpeer agent`: its flags and the fast path that starts an agent.

`sdrpeer agent` flags map one-to-one onto `AgentConfig` fields (`--key-file` -> `key_file`);
`--config FILE` supplies the same fields from YAML and flags override it. This module imports
only what parsing needs: `python -m sdrpeer agent ...` (see `sdrpeer.__main__`) comes here without
loading the client commands, and the agent itself (`sdrpeer.agent.main`) is imported once the
flags are read.
"""

from __future__ import annotations

import argparse
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sdrpeer.config import (
    AGENT_PRESET,
    FIELDS,
    LOG_FORMATS,
    LOG_LEVELS,
    PRESET_NAMES,
    build_config,
    load_agent_config,
    presets_epilog,
)
from sdrpeer.errors import ConfigError


def add_agent_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`sdrpeer agent`: one flag per AgentConfig field."""
    p = sub.add_parser(
        "agent",
        help="run the agent of one robot",
        description=__doc__,
        epilog=presets_epilog(AGENT_PRESET),
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.set_defaults(func=cmd_agent)
    p.add_argument("--config", type=Path, metavar="FILE", help="agent config file (YAML)")
    p.add_argument("--name", help="this robot's name ([A-Za-z0-9_.-]+)")
    p.add_argument("--bind", metavar="HOST:PORT", help="gossip UDP (127.0.0.1:7946)")
    p.add_argument("--join", action="append", metavar="HOST:PORT", help="a member to join; repeat")
    p.add_argument("--api", metavar="HOST:PORT", help="HTTP API address (default 127.0.0.1:8080)")
    p.add_argument("--robot-file", type=Path, metavar="FILE", help="virtual robot's facts (YAML)")
    p.add_argument("--scenario", type=Path, metavar="FILE", help="scenario for the virtual robot")
    p.add_argument("--key-file", type=Path, metavar="FILE", help="cluster key (hex)")
    p.add_argument(
        "--insecure",
        action="store_true",
        default=None,
        help="run without a cluster key: gossip open to all, no calls between robots",
    )
    p.add_argument(
        "--allow-launchers",
        "--allow-launcher",
        dest="allow_launchers",
        action="append",
        metavar="NAME",
        help="a launcher hosts may use besides python (exec, script, a plugin): off unless named",
    )
    p.add_argument(
        "--allow-targets",
        "--allow-target",
        dest="allow_targets",
        action="append",
        metavar="PATTERN",
        help="python targets allowed (shell pattern on package.module:Class; default *); repeat",
    )
    p.add_argument("--token-file", type=Path, metavar="FILE", help="API token (default: generate)")
    p.add_argument(
        "--preset",
        choices=PRESET_NAMES,
        help=f"every timer's preset (default {AGENT_PRESET}; the list below)",
    )
    p.add_argument("--data-dir", type=Path, metavar="DIR", help="state directory")
    p.add_argument("--metrics-interval", type=float, metavar="SECONDS", help="metrics period")
    p.add_argument(
        "--scenario-start",
        type=float,
        metavar="UNIX_TIME",
        help="the scenario's time 0 (default: this agent's start; the lab passes its own)",
    )
    p.add_argument("--priority", type=_priority, metavar="N", help="election priority (default 0)")
    p.add_argument(
        "--preempt",
        action="store_true",
        default=None,
        help="take the allocator role from a lower-ranked allocator at any time, not only at start",
    )
    p.add_argument("--log-level", choices=LOG_LEVELS, help="default info")
    p.add_argument("--log-format", choices=LOG_FORMATS, help="default text")
    p.add_argument(
        "--ros2-domain",
        type=int,
        choices=range(102),
        metavar="0..101",
        help="the fleet's ROS 2 domain for ros2 hosts (default: $ROS_DOMAIN_ID, else a fixed one)",
    )
    p.add_argument(
        "--discover",
        action=argparse.BooleanOptionalAction,
        default=None,
        help="find the fleet on the local network by mDNS (default off; the key still rules)",
    )


def agent_flag_values(args: argparse.Namespace) -> dict[str, Any]:
    """The AgentConfig fields given as flags (None = not given)."""
    return {field: getattr(args, field, None) for field in FIELDS}


def cmd_agent(args: argparse.Namespace) -> int:
    """Build the configuration and run the agent until it is told to stop."""
    file_values = load_agent_config(args.config) if args.config else None
    config = build_config(file_values, agent_flag_values(args))
    from sdrpeer.agent.main import run_agent  # noqa: PLC0415 - heavy; only `agent` needs it

    return run_agent(config)


def main(argv: Sequence[str]) -> int:
    """`sdrpeer agent ARGS` without the rest of the command line (exit codes as `sdrpeer`)."""
    parser = argparse.ArgumentParser(prog="sdrpeer")
    add_agent_parser(parser.add_subparsers(dest="command", required=True, metavar="COMMAND"))
    args = parser.parse_args(["agent", *argv])
    try:
        return cmd_agent(args)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        return 130


def _priority(text: str) -> int:
    """--priority: an integer within the record's range."""
    from sdrpeer.record.limits import check_int  # noqa: PLC0415 - the fast path imports little

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    try:
        return check_int("priority", n)
    except ValueError as e:
        raise argparse.ArgumentTypeError(str(e)) from None
