"""`sdrpeer deploy FILE [--wait]`, `status [--json]`, `undeploy`, `move COMPONENT [--to ROBOT]`,
`describe COMPONENT|ROBOT`.

How it works: `deploy` loads and validates the system file here first (every problem with
file:line; nothing is sent when one is found), then posts the system to an agent, which hands
it to the allocator. `--wait` polls `GET /v1/status` on the same agent and prints each change of
a component's robot or state until all are ACTIVE, or fails after `--timeout` naming the ones
that are not. `move` asks the allocator for a planned move of one component's active instance
(the old instance hands its state and its untaken frames to the new one) and, with `--wait`,
returns once the component is ACTIVE on its new robot. `describe` prints one
`GET /v1/describe/{name}` (`sdrpeer.cli.describe` lays it out).
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
import urllib.parse
from pathlib import Path
from typing import Any

from sdrpeer.cli.common import client_for
from sdrpeer.cli.format import want_color
from sdrpeer.client import ELECTION_WAIT, AgentClient, post_when_elected
from sdrpeer.errors import SdrpeerError
from sdrpeer.vocabulary import InstanceRole, LifecycleState

WAIT_POLL = 0.1
"""How long deploy/undeploy retry while no allocator is elected yet (a lab just started)."""


def add_deploy_parsers(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    client: argparse.ArgumentParser,
    as_json: argparse.ArgumentParser,
) -> None:
    """Register deploy, status and undeploy."""
    deploy = sub.add_parser("deploy", parents=[client, as_json], help="deploy a system file")
    deploy.add_argument("file", type=Path, help="system file (YAML, docs/system-file.md)")
    deploy.add_argument("--wait", action="store_true", help="return when all are ACTIVE")
    deploy.add_argument("--timeout", type=float, default=120.0, metavar="S", help="for --wait")
    deploy.set_defaults(func=cmd_deploy)
    status = sub.add_parser("status", parents=[client, as_json], help="where each component runs")
    status.set_defaults(func=cmd_status)
    undeploy = sub.add_parser("undeploy", parents=[client, as_json], help="stop the system")
    undeploy.set_defaults(func=cmd_undeploy)
    move = sub.add_parser("move", parents=[client, as_json], help="move a component (planned)")
    move.add_argument("component", help="the component's name in the system file")
    move.add_argument("--to", metavar="ROBOT", help="destination (default: the allocator's pick)")
    move.add_argument("--wait", action="store_true", help="return when ACTIVE there")
    move.add_argument("--timeout", type=float, default=60.0, metavar="S", help="for --wait")
    move.set_defaults(func=cmd_move)
    describe = sub.add_parser(
        "describe", parents=[client, as_json], help="where a component runs and why, or a robot"
    )
    describe.add_argument("name", help="a component, an instance or a robot")
    describe.set_defaults(func=cmd_describe)


def _client(args: argparse.Namespace) -> AgentClient:

    return client_for(args)


def cmd_deploy(args: argparse.Namespace) -> int:
    """Validate, send, and optionally wait for every component to be ACTIVE."""
    from sdrpeer.system.loader import load_system  # noqa: PLC0415 - yaml + plugins: only here

    system = load_system(args.file)
    client = _client(args)
    t0 = time.monotonic()
    answer = post_when_elected(client, "/v1/deploy", {"system": system.to_json()}, args.timeout)
    plan = answer.get("plan", {}) if isinstance(answer, dict) else {}
    if args.json and not args.wait:
        print(json.dumps(answer, indent=2, sort_keys=True))
        return 0
    print(
        f"deployed {system.name!r}: plan epoch {plan.get('epoch')} version {plan.get('version')}"
        f" by {answer.get('allocator')}"
    )
    for comp, inst, robot, role, mode in plan.get("placements", []):
        extra = f" ({mode})" if role == InstanceRole.STANDBY else ""
        print(f"  {comp:<28} {inst:<32} -> {robot} {role}{extra}")
    if not args.wait:
        return 0
    key = (plan.get("epoch", 0), plan.get("version", 0))
    return _wait(client, t0, args.timeout, key, json_out=args.json)


def _wait(
    client: AgentClient, t0: float, timeout: float, key: tuple[int, int], *, json_out: bool
) -> int:
    """Poll status until the deployed plan (or a newer one) is all ACTIVE."""
    from sdrpeer.deploy.status import all_active  # noqa: PLC0415 - the parser stays light
    from sdrpeer.record.robot import state_to_wire  # noqa: PLC0415

    seen: dict[str, tuple[Any, Any]] = {}
    doc: dict[str, Any] = {}
    while time.monotonic() - t0 < timeout:
        doc = client.get("/v1/status")
        held = doc.get("plan") or {}
        if (held.get("epoch", 0), held.get("version", 0)) < key:
            time.sleep(WAIT_POLL)  # this agent has not received the deployed plan yet
            continue
        for c in doc.get("components", []):
            now = (c.get("robot"), c.get("state"))
            if seen.get(c["component"]) != now and not json_out:
                print(f"  {time.monotonic() - t0:6.2f}s {c['component']:<28} {now[0]} {now[1]}")
            seen[c["component"]] = now
        if all_active(doc):
            elapsed = time.monotonic() - t0
            if json_out:
                print(json.dumps({"elapsed_s": round(elapsed, 3), "status": doc}, indent=2))
            else:
                print(f"all {len(seen)} components ACTIVE after {elapsed:.2f}s")
            return 0
        time.sleep(WAIT_POLL)
    waiting = [
        c["component"]
        for c in doc.get("components", [])
        if c.get("state") != state_to_wire(LifecycleState.ACTIVE)
    ]
    raise SdrpeerError(f"not ACTIVE after {timeout:.0f}s: {', '.join(waiting) or 'no plan yet'}")


def cmd_status(args: argparse.Namespace) -> int:
    """Print where each component runs."""
    doc = _client(args).get("/v1/status")
    if args.json:
        print(json.dumps(doc, indent=2, sort_keys=True))
    else:
        from sdrpeer.cli.status import format_status  # noqa: PLC0415 - the table only

        print(format_status(doc, color=want_color(sys.stdout.isatty(), os.environ)))
    return 0


def cmd_describe(args: argparse.Namespace) -> int:
    """Print why a component is where it is (or what a robot hosts and how it fares)."""
    from sdrpeer.cli.describe import format_describe  # noqa: PLC0415 - only this command

    doc = _client(args).get(f"/v1/describe/{urllib.parse.quote(args.name, safe='')}")
    if args.json:
        print(json.dumps(doc, indent=2, sort_keys=True))
    else:
        print(format_describe(doc, color=want_color(sys.stdout.isatty(), os.environ)))
    return 0


def cmd_undeploy(args: argparse.Namespace) -> int:
    """Ask the allocator for an empty plan."""
    answer = post_when_elected(_client(args), "/v1/undeploy", {}, ELECTION_WAIT)
    plan = answer.get("plan", {}) if isinstance(answer, dict) else {}
    print(f"undeployed: plan epoch {plan.get('epoch')} version {plan.get('version')}")
    return 0


def cmd_move(args: argparse.Namespace) -> int:
    """Ask for a planned move; with --wait, poll until the component is ACTIVE there."""
    from sdrpeer.record.robot import state_to_wire  # noqa: PLC0415 - the parser stays light

    client = _client(args)
    t0 = time.monotonic()
    body = {"component": args.component, **({"to": args.to} if args.to else {})}
    answer = post_when_elected(client, "/v1/move", body, args.timeout)
    robot, instance = answer.get("robot"), answer.get("instance")
    if not args.json:
        print(
            f"moving {args.component}: {instance} -> {robot} (allocator {answer.get('allocator')})"
        )
    if not args.wait:
        if args.json:
            print(json.dumps(answer, indent=2, sort_keys=True))
        return 0
    while time.monotonic() - t0 < args.timeout:
        doc = client.get("/v1/status")
        rows: list[dict[str, Any]] = doc.get("components", [])
        row = next((c for c in rows if c["component"] == args.component), {})
        if row.get("robot") == robot and row.get("state") == state_to_wire(LifecycleState.ACTIVE):
            elapsed = time.monotonic() - t0
            if args.json:
                print(json.dumps({"elapsed_s": round(elapsed, 3), **answer}, indent=2))
            else:
                print(f"{args.component} ACTIVE on {robot} after {elapsed:.2f}s")
            return 0
        time.sleep(WAIT_POLL)
    raise SdrpeerError(f"{args.component} not ACTIVE on {robot} after {args.timeout:.0f}s")
