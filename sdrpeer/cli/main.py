"""The `sdrpeer` command: the client commands, and (via `sdrpeer.cli.lab`) lab and demo.

`sdrpeer agent` has its own light module (`sdrpeer.cli.agent`): `python -m sdrpeer agent` goes
there without loading the rest of the command line, so an agent starts fast. Client commands find
the agent with `--api`, `$SDRPEER_API` or the lab file, see `sdrpeer.client`.
Exit codes: 0 ok, 1 an operation failed, 2 bad configuration or usage, 130 interrupted.

How it works: the commands come in groups, each registered by one function (`GROUPS`: the
command names and the function that adds their parsers, importing its module only then). When
the first word is a command of a group, `main` builds the parser with that group alone: the
same parser for that command (the same flags, help and errors), without importing or building
the forty others (`sdrpeer status --json` is one interpreter start, one request and a print);
anything else (`--help`, a typo, a command a later feature adds to `build_parser` directly)
gets the whole parser.
"""

from __future__ import annotations

import argparse
import importlib
import json
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, TypeAlias

from sdrpeer import __version__
from sdrpeer.cli.common import (
    client_for,
    client_options,
    parse_assignment,
    print_json,
    robot_client,
)
from sdrpeer.errors import ApiError, ConfigError, SdrpeerError

if TYPE_CHECKING:
    Subparsers: TypeAlias = argparse._SubParsersAction[argparse.ArgumentParser]
    Register: TypeAlias = Callable[
        [Subparsers, argparse.ArgumentParser, argparse.ArgumentParser], None
    ]

EVENTS_POLL = 0.5


# --- client commands -------------------------------------------------------------------------


def cmd_members(args: argparse.Namespace) -> int:
    """Print the members table (or the raw list with --json)."""
    members = client_for(args).members()
    if args.json:
        print_json(members)
    else:
        from sdrpeer.cli.format import format_members, want_color  # noqa: PLC0415 - tables only

        print(format_members(members, color=want_color(sys.stdout.isatty(), os.environ)))
    return 0


def cmd_agent_info(args: argparse.Namespace) -> int:
    """Print the agent's own counters."""
    agent = client_for(args).agent()
    if args.json:
        print_json(agent)
    else:
        from sdrpeer.cli.format import format_agent  # noqa: PLC0415 - tables only

        print(format_agent(agent))
    return 0


def cmd_events(args: argparse.Namespace) -> int:
    """Print the event log; with --follow keep polling until Ctrl-C."""
    from sdrpeer.cli.format import format_event, want_color  # noqa: PLC0415 - not for --help

    client = client_for(args)
    color = want_color(sys.stdout.isatty(), os.environ)
    since = args.since
    try:
        while True:
            batch = client.events(since=since, limit=500)
            for event in batch:
                line = format_event(event, color=color)
                print(json.dumps(event, sort_keys=True) if args.json else line)
                since = max(since, int(event.get("id", since)))
            sys.stdout.flush()
            if len(batch) == 500:
                continue
            if not args.follow:
                return 0
            time.sleep(EVENTS_POLL)
    except KeyboardInterrupt:
        return 0


def cmd_robot_set(args: argparse.Namespace) -> int:
    """Change a virtual robot's facts live: sdrpeer robot set robot-1 rssi=-55dBm battery=30%."""
    from sdrpeer.cli.format import format_metrics  # noqa: PLC0415 - not for --help

    changes = dict(parse_assignment(a) for a in args.assignments)
    answer = robot_client(args).post("/v1/robot", changes)
    if args.json:
        print_json(answer)
    else:
        metrics = answer.get("metrics") if isinstance(answer, dict) else None
        print(f"{args.robot}: set {', '.join(args.assignments)}")
        if metrics:
            print(f"  now: {format_metrics(metrics)}")
    return 0


def add_client_parsers(
    sub: Subparsers, client: argparse.ArgumentParser, as_json: argparse.ArgumentParser
) -> None:
    """Register members, agent-info, events and robot (this module's commands)."""
    members = sub.add_parser("members", parents=[client, as_json], help="list the members")
    members.set_defaults(func=cmd_members)
    info = sub.add_parser("agent-info", parents=[client, as_json], help="the agent's counters")
    info.set_defaults(func=cmd_agent_info)
    events = sub.add_parser("events", parents=[client, as_json], help="the event log")
    events.add_argument("--follow", "-f", action="store_true", help="keep printing new events")
    events.add_argument("--since", type=int, default=0, metavar="ID", help="only events after ID")
    events.set_defaults(func=cmd_events)
    robot = sub.add_parser("robot", help="change a virtual robot")
    robot_sub = robot.add_subparsers(dest="robot_command", required=True, metavar="ACTION")
    robot_set = robot_sub.add_parser("set", parents=[client, as_json], help="set facts live")
    robot_set.add_argument("robot", help="robot name, e.g. robot-1")
    robot_set.add_argument("assignments", nargs="+", metavar="KEY=VALUE", help="e.g. battery=30%%")
    robot_set.set_defaults(func=cmd_robot_set)


def _lazy(module: str, name: str, *parents: str) -> Register:
    """A group's registration that imports `module` only when the group is asked for, then calls
    its `name` with the subparsers and the shared parents it takes ("client", "as_json")."""

    def register(
        sub: Subparsers, client: argparse.ArgumentParser, as_json: argparse.ArgumentParser
    ) -> None:
        given = {"client": client, "as_json": as_json}
        add = getattr(importlib.import_module(module), name)
        add(sub, *(given[p] for p in parents))

    return register


GROUPS: tuple[tuple[tuple[str, ...], Register], ...] = (
    (("agent",), _lazy("sdrpeer.cli.agent", "add_agent_parser")),
    (("members", "agent-info", "events", "robot"), add_client_parsers),
    (
        ("instances", "logs", "start-instance", "run"),
        _lazy("sdrpeer.cli.instances", "add_instance_parsers", "client", "as_json"),
    ),
    (
        ("deploy", "status", "undeploy", "move", "describe"),
        _lazy("sdrpeer.cli.deploy", "add_deploy_parsers", "client", "as_json"),
    ),
    (("port",), _lazy("sdrpeer.cli.port", "add_port_parsers", "client", "as_json")),
    (("system",), _lazy("sdrpeer.cli.system", "add_system_parser")),
    (("lab", "demo"), _lazy("sdrpeer.cli.lab", "add_lab_parsers")),
    (("top",), _lazy("sdrpeer.cli.top", "add_top_parser", "client")),
    (("profile",), _lazy("sdrpeer.cli.profile", "add_profile_parser")),
    (("keygen", "key"), _lazy("sdrpeer.cli.keys", "add_key_parsers", "client", "as_json")),
    (("systemd-unit",), _lazy("sdrpeer.cli.service", "add_service_parser")),
)
"""Every command, in `sdrpeer --help` order, by the function that registers it and its group
(tests/test_cli_fast.py holds each group to the commands its function adds)."""


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The `sdrpeer` argument parser: every command, or only the group of `command`."""
    parser = argparse.ArgumentParser(prog="sdrpeer", description="A leaderless robot platform.")
    parser.add_argument("--version", action="version", version=f"sdrpeer {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    client = client_options()
    as_json = argparse.ArgumentParser(add_help=False)
    as_json.add_argument("--json", action="store_true", help="print JSON")
    for names, register in GROUPS:
        if command is None or command in names:
            register(sub, client, as_json)
    return parser


def _group_of(argv: Sequence[str]) -> str | None:
    """The command `argv` starts with when a group registers it, else None (whole parser)."""
    first = argv[0] if argv else None
    return first if any(first in names for names, _ in GROUPS) else None


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `sdrpeer` console script."""
    argv = list(sys.argv[1:] if argv is None else argv)
    args = build_parser(_group_of(argv)).parse_args(argv)
    try:
        return int(args.func(args))
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    except (ApiError, SdrpeerError) as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        return 130
    except BrokenPipeError:
        # stdout was closed early (e.g. `sdrpeer members --json | head`): not an error.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 0
