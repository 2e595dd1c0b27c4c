"""The `sdrpeer` command: the client commands, and (via `sdrpeer.cli_lab`) lab and demo.

`sdrpeer agent` has its own light module (`sdrpeer.agent_cli`): `python -m sdrpeer agent` goes
there without loading the rest of the command line, so an agent starts fast. Client commands find
the agent with `--api`, `$SDRPEER_API` or the lab file, see `sdrpeer.client`.
Exit codes: 0 ok, 1 an operation failed, 2 bad configuration or usage, 130 interrupted.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from sdrpeer import __version__
from sdrpeer.agent_cli import add_agent_parser
from sdrpeer.cli_format import (
    format_agent,
    format_event,
    format_members,
    format_metrics,
    want_color,
)
from sdrpeer.client import AgentClient, Endpoint, resolve_endpoint
from sdrpeer.errors import ApiError, ConfigError, SdrpeerError
from sdrpeer.lab import DEFAULT_DIR, read_lab

EVENTS_POLL = 0.5


# --- client commands -------------------------------------------------------------------------


def _client_options() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--api", metavar="URL", help="agent API (default $SDRPEER_API, else the lab)")
    p.add_argument("--token", help="API token (default $SDRPEER_TOKEN, else the lab file)")
    p.add_argument("--lab-dir", type=Path, default=DEFAULT_DIR, metavar="DIR", help="lab directory")
    return p


def endpoint(args: argparse.Namespace) -> Endpoint:
    """Where this client command sends its calls."""
    return resolve_endpoint(args.api, args.token, args.lab_dir, os.environ)


def client_for(args: argparse.Namespace) -> AgentClient:
    """An AgentClient for the resolved endpoint."""
    found = endpoint(args)
    return AgentClient(found.api, found.token)


def _print_json(value: Any) -> None:
    print(json.dumps(value, indent=2, sort_keys=True))


def cmd_members(args: argparse.Namespace) -> int:
    """Print the members table (or the raw list with --json)."""
    members = client_for(args).members()
    if args.json:
        _print_json(members)
    else:
        print(format_members(members, color=want_color(sys.stdout.isatty(), os.environ)))
    return 0


def cmd_agent_info(args: argparse.Namespace) -> int:
    """Print the agent's own counters."""
    agent = client_for(args).agent()
    if args.json:
        _print_json(agent)
    else:
        print(format_agent(agent))
    return 0


def cmd_events(args: argparse.Namespace) -> int:
    """Print the event log; with --follow keep polling until Ctrl-C."""
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


def parse_assignment(text: str) -> tuple[str, Any]:
    """'battery=30%' -> ('battery', '30%'); numbers become numbers; 'pos=3,4' -> [3, 4]."""
    key, sep, value = text.partition("=")
    if not sep or not key or not value:
        raise ConfigError(f"{text!r}: expected key=value, e.g. battery=30% or rssi=-55dBm")

    def scalar(item: str) -> Any:
        for kind in (int, float):
            try:
                return kind(item)
            except ValueError:
                pass
        return item

    if "," in value:
        return key, [scalar(v.strip()) for v in value.split(",")]
    return key, scalar(value)


def robot_client(args: argparse.Namespace) -> AgentClient:
    """The client for the robot named by args.robot: its lab entry, else its `api` member field."""
    lab = None if (args.api or os.environ.get("SDRPEER_API")) else read_lab(args.lab_dir)
    entry = lab.robot(args.robot) if lab else None
    if entry is not None and entry.api:
        return AgentClient(entry.api, args.token or os.environ.get("SDRPEER_TOKEN") or entry.token)
    found = endpoint(args)
    members = AgentClient(found.api, found.token).members()
    member = next((m for m in members if m.get("name") == args.robot), None)
    if member is None:
        known = ", ".join(str(m.get("name")) for m in members)
        raise SdrpeerError(f"no robot {args.robot!r} in the cluster (members: {known})")
    if not member.get("api"):
        raise SdrpeerError(f"{args.robot} does not publish an API address; pass --api URL")
    again = resolve_endpoint(str(member["api"]), args.token, args.lab_dir, os.environ)
    return AgentClient(again.api, again.token)


def cmd_robot_set(args: argparse.Namespace) -> int:
    """Change a virtual robot's facts live: sdrpeer robot set robot-1 rssi=-55dBm battery=30%."""
    changes = dict(parse_assignment(a) for a in args.assignments)
    answer = robot_client(args).post("/v1/robot", changes)
    if args.json:
        _print_json(answer)
    else:
        metrics = answer.get("metrics") if isinstance(answer, dict) else None
        print(f"{args.robot}: set {', '.join(args.assignments)}")
        if metrics:
            print(f"  now: {format_metrics(metrics)}")
    return 0


def build_parser() -> argparse.ArgumentParser:
    """The whole `sdrpeer` argument parser."""
    from sdrpeer.cli_lab import add_lab_parsers  # noqa: PLC0415 - cli_lab imports this module
    from sdrpeer.cli_top import add_top_parser  # noqa: PLC0415 - same
    from sdrpeer.deploy.commands import add_deploy_parsers  # noqa: PLC0415 - same
    from sdrpeer.profile import add_profile_parser  # noqa: PLC0415 - heavy: only when parsing
    from sdrpeer.runtime.commands import add_instance_parsers  # noqa: PLC0415 - same
    from sdrpeer.system.commands import add_system_parser  # noqa: PLC0415 - same

    parser = argparse.ArgumentParser(prog="sdrpeer", description="A leaderless robot platform.")
    parser.add_argument("--version", action="version", version=f"sdrpeer {__version__}")
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    add_agent_parser(sub)
    client = _client_options()
    as_json = argparse.ArgumentParser(add_help=False)
    as_json.add_argument("--json", action="store_true", help="print JSON")
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
    add_instance_parsers(sub, client, as_json)
    add_deploy_parsers(sub, client, as_json)
    add_system_parser(sub)
    add_lab_parsers(sub)
    add_top_parser(sub, client)
    add_profile_parser(sub)  # `sdrpeer profile` (components issue; lives in sdrpeer.profile)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the `sdrpeer` console script."""
    args = build_parser().parse_args(argv)
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
