"""What every client command of `sdrpeer` shares: finding the agent, printing JSON, KEY=VALUE."""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
from typing import Any

from sdrpeer.client import LAB_DIR, AgentClient, Endpoint, resolve_endpoint
from sdrpeer.errors import ConfigError, SdrpeerError


def client_options() -> argparse.ArgumentParser:
    """The options every client command takes: --api, --token, --lab-dir."""
    p = argparse.ArgumentParser(add_help=False)
    p.add_argument("--api", metavar="URL", help="agent API (default $SDRPEER_API, else the lab)")
    p.add_argument("--token", help="API token (default $SDRPEER_TOKEN, else the lab file)")
    p.add_argument("--lab-dir", type=Path, default=LAB_DIR, metavar="DIR", help="lab directory")
    return p


def endpoint(args: argparse.Namespace) -> Endpoint:
    """Where this client command sends its calls."""
    return resolve_endpoint(args.api, args.token, args.lab_dir, os.environ)


def client_for(args: argparse.Namespace) -> AgentClient:
    """An AgentClient for the resolved endpoint."""
    found = endpoint(args)
    return AgentClient(found.api, found.token)


def print_json(value: Any) -> None:
    """Print `value` as indented, sorted JSON."""
    print(json.dumps(value, indent=2, sort_keys=True))


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
    from sdrpeer.lab.files import read_lab  # noqa: PLC0415 - the watching commands do without

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
