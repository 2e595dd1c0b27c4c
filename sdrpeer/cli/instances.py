"""The instance commands of `sdrpeer`: instances, logs, start-instance, run.

How it works: each command is a thin client of the agent's /v1/instances routes (found like every
client command: --api, $SDRPEER_API or the lab; `run` asks for the robot by name). `logs` reads
text, not JSON, so it makes its own urllib call; `-f` keeps the chunked response open and prints
what arrives until Ctrl-C.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
import urllib.error
import urllib.parse
import urllib.request
from pathlib import Path
from typing import Any

from sdrpeer.cli.common import client_for, endpoint, parse_assignment, print_json, robot_client
from sdrpeer.cli.format import format_instances, want_color
from sdrpeer.client import unreachable_message
from sdrpeer.errors import ApiError
from sdrpeer.vocabulary import LifecycleState

LAUNCHER_HELP = "python (default), script, exec, composite or a plugin"
"""`--launcher`'s help: the built-in launchers (`sdrpeer.runtime.spec.LAUNCHERS`, held to it by
tests/test_cli_fast.py) without importing the instance specs to say it."""


def cmd_instances(args: argparse.Namespace) -> int:
    """Print the instances table (or the raw list with --json)."""
    instances = client_for(args).get("/v1/instances")
    if args.json:
        print_json(instances)
    else:
        color = want_color(sys.stdout.isatty(), os.environ)
        print(format_instances(instances, now=time.time(), color=color))
    return 0


def cmd_logs(args: argparse.Namespace) -> int:
    """Print an instance's log; with -f keep printing until Ctrl-C."""
    found = endpoint(args)
    query = {"tail": args.tail, **({"follow": 1} if args.follow else {})}
    name = urllib.parse.quote(args.instance, safe="")
    url = f"{found.api}/v1/instances/{name}/logs?{urllib.parse.urlencode(query)}"
    try:
        with urllib.request.urlopen(url, timeout=None if args.follow else 10) as response:
            while chunk := response.read1(65536):
                sys.stdout.buffer.write(chunk)
                sys.stdout.flush()
    except urllib.error.HTTPError as exc:
        raise ApiError(f"agent at {found.api} answered {exc.code}: {exc.reason}") from None
    except urllib.error.URLError as exc:
        raise ApiError(unreachable_message(found.api, exc.reason)) from None
    except KeyboardInterrupt:
        return 0
    return 0


def instance_doc(args: argparse.Namespace) -> dict[str, Any]:
    """The spec JSON that start-instance posts."""
    from sdrpeer.runtime.spec import InstanceSpec, desired_to_json  # noqa: PLC0415 - not to list

    doc: dict[str, Any] = {
        "name": args.name,
        "launcher": args.launcher,
        "target": args.target.split() if args.launcher == "exec" else args.target,
        "params": dict(parse_assignment(p) for p in args.param),
        "desired": desired_to_json(
            LifecycleState.INACTIVE if args.inactive else LifecycleState.ACTIVE
        ),
    }
    if args.component:
        doc["component"] = args.component
    InstanceSpec.from_json(doc, "instance")  # the same errors locally, before any call
    return doc


def cmd_start_instance(args: argparse.Namespace) -> int:
    """Add one instance to the agent's desired set."""
    answer = client_for(args).post("/v1/instances", {"instances": [instance_doc(args)]})
    if args.json:
        print_json(answer)
    else:
        print(f"{args.name}: desired; now: {', '.join(answer.get('desired', []))}")
    return 0


def cmd_run(args: argparse.Namespace) -> int:
    """Run a whole system file on one robot, no allocator (replaces that robot's desired set)."""
    from sdrpeer.deploy.one_robot import load_on_one_robot  # noqa: PLC0415 - imports plugins

    specs = load_on_one_robot(args.file, args.robot)
    body = {"instances": [s.to_json() for s in specs], "replace": True}
    answer = robot_client(args).post("/v1/instances", body)
    if args.json:
        print_json(answer)
    else:
        names = ", ".join(s.name for s in specs)
        print(f"{args.robot}: running {args.file} ({names}); watch with: sdrpeer instances")
    return 0


def add_instance_parsers(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    client: argparse.ArgumentParser,
    as_json: argparse.ArgumentParser,
) -> None:
    """Register instances, logs, start-instance and run."""
    p = sub.add_parser("instances", parents=[client, as_json], help="this robot's instances")
    p.set_defaults(func=cmd_instances)
    p = sub.add_parser("logs", parents=[client], help="an instance's log")
    p.add_argument("instance", help="instance name")
    p.add_argument("-f", "--follow", action="store_true", help="keep printing new output")
    p.add_argument("--tail", type=int, default=100, metavar="N", help="last N lines (100)")
    p.set_defaults(func=cmd_logs)
    p = sub.add_parser("start-instance", parents=[client, as_json], help="start one instance")
    p.add_argument("--name", required=True, help="instance name, e.g. Cam1")
    p.add_argument("--target", required=True, help="pkg.mod:Class (exec: a command line)")
    p.add_argument("--launcher", default="python", help=LAUNCHER_HELP)
    p.add_argument("--component", help="logical component name (default: the class name)")
    p.add_argument("--param", action="append", default=[], metavar="K=V", help="repeatable")
    p.add_argument("--inactive", action="store_true", help="start it but do not activate it")
    p.set_defaults(func=cmd_start_instance)
    p = sub.add_parser("run", parents=[client, as_json], help="run a system file on a robot")
    p.add_argument("file", type=Path, help="system file (YAML: components, connections)")
    p.add_argument("--robot", required=True, help="the robot to run everything on")
    p.set_defaults(func=cmd_run)
