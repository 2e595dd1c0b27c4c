"""The key commands of `sdrpeer`: keygen, and key list|add|primary|retire|rotate on a running
fleet (Serf's `serf keygen` and `serf keys -list|-install|-use|-remove`).

How it works: `keygen` prints a new random 32-byte cluster key as a key-file line (hex), what
`--key-file` reads. The `key` commands ask one agent (its API token, found like every client
command's) which applies the change on every alive robot and answers robot by robot
(sdrpeer.agent.keyadmin); they exit 1 unless every robot took it. A new key is read from a file
(`sdrpeer keygen > new.key`; `-` for standard input), never from the command line, where `ps`
and shell histories would show it; it travels to the agent in the request body, so ask an
agent on loopback (or through ssh). Keys are named by their 8-hex-digit id (`key list`) or by
a key file. `rotate` is add, primary and retire of every other key, one after the other.
"""

from __future__ import annotations

import argparse
import binascii
import sys
from pathlib import Path
from typing import Any

from sdrpeer.cli.common import client_for, print_json
from sdrpeer.cli.format import render_table
from sdrpeer.client import AgentClient
from sdrpeer.errors import ConfigError, SdrpeerError
from sdrpeer.keys.keyring import Keyring, format_key, key_id, parse_key, parse_key_id

FLEET_TIMEOUT = 30.0
"""Seconds the CLI waits for a fleet change (the agent tries each robot a few times)."""


def cmd_keygen(args: argparse.Namespace) -> int:
    """Print a new cluster key (a key-file line)."""
    print(format_key(Keyring.generate()))
    return 0


def read_key(source: str) -> bytes:
    """The first key of a key file (`-`: standard input)."""
    if source == "-":
        return Keyring([_first_key_line(sys.stdin.read())]).signing_key
    return Keyring.from_file(Path(source)).signing_key


def _first_key_line(text: str) -> bytes:
    for raw in text.splitlines():
        line = raw.split("#", 1)[0].strip()
        if line:
            try:
                return parse_key(line)
            except (ValueError, binascii.Error):
                raise ConfigError("standard input: not a hex or base64 key") from None
    raise ConfigError("standard input: no key")


def key_ref(text: str) -> bytes:
    """A key id from an id (8 hex digits) or a key file."""
    if Path(text).is_file() or text == "-":
        return key_id(read_key(text))
    try:
        return parse_key_id(text)
    except ValueError as exc:
        raise ConfigError(f"{exc}, or a key file") from None


def _fleet(args: argparse.Namespace) -> AgentClient:
    client = client_for(args)
    return AgentClient(client.base, client.token, timeout=FLEET_TIMEOUT)


def format_listing(listing: dict[str, Any]) -> str:
    """Which robots hold and seal with which key."""
    robots = listing.get("robots", {})
    keys: dict[str, list[str]] = {}
    primary: dict[str, list[str]] = {}
    problems = []
    for robot, doc in robots.items():
        if "error" in doc:
            problems.append(f"{robot}: no answer ({doc['error']})")
            continue
        for kid in doc.get("keys", []):
            keys.setdefault(kid, []).append(robot)
        primary.setdefault(str(doc.get("primary")), []).append(robot)
    n = len(robots)
    rows = [
        [kid, f"{len(holders)}/{n}", f"{len(primary.get(kid, []))}/{n}", ", ".join(holders)]
        for kid, holders in sorted(keys.items(), key=lambda kv: -len(primary.get(kv[0], [])))
    ]
    out = [render_table(["KEY ID", "INSTALLED", "PRIMARY", "ROBOTS"], rows)]
    out += problems
    out += [f"{robot}: not alive (not asked)" for robot in listing.get("not_alive", [])]
    return "\n".join(out)


def format_change(answer: dict[str, Any]) -> str:
    """One line per robot: its ring after the change, or what went wrong."""
    lines = [f"key {answer.get('op')} {answer.get('key_id')}:"]
    for robot, doc in answer.get("robots", {}).items():
        if "error" in doc:
            lines.append(f"  {robot}: FAILED: {doc['error']}")
        else:
            lines.append(f"  {robot}: primary {doc['primary']}, keys {', '.join(doc['keys'])}")
    lines += [f"  {robot}: not alive: missed it" for robot in answer.get("not_alive", [])]
    return "\n".join(lines)


def _change(args: argparse.Namespace, body: dict[str, Any]) -> int:
    answer = _fleet(args).post("/v1/keys/fleet", body)
    if args.json:
        print_json(answer)
    else:
        print(format_change(answer))
    return 0 if answer.get("ok") else 1


def cmd_key_list(args: argparse.Namespace) -> int:
    """Every robot's keys."""
    listing = _fleet(args).get("/v1/keys/fleet")
    if args.json:
        print_json(listing)
    else:
        print(format_listing(listing))
    return 0


def cmd_key_add(args: argparse.Namespace) -> int:
    """Install a key on every robot (it opens; it does not seal yet)."""
    return _change(args, {"op": "add", "key": format_key(read_key(args.key_file))})


def cmd_key_primary(args: argparse.Namespace) -> int:
    """Make a key the one every robot seals with."""
    return _change(args, {"op": "primary", "key_id": key_ref(args.key).hex()})


def cmd_key_retire(args: argparse.Namespace) -> int:
    """Remove a key from every robot."""
    return _change(args, {"op": "retire", "key_id": key_ref(args.key).hex()})


def cmd_key_rotate(args: argparse.Namespace) -> int:
    """add, primary, then retire every other key: the whole fleet on the new key."""
    key = read_key(args.key_file)
    kid = key_id(key).hex()
    steps: list[dict[str, Any]] = [
        {"op": "add", "key": format_key(key)},
        {"op": "primary", "key_id": kid},
    ]
    for body in steps:
        if _change(args, body):
            raise SdrpeerError(f"rotation stopped at {body['op']}: see above")
    listing = _fleet(args).get("/v1/keys/fleet")
    old = sorted({k for d in listing["robots"].values() for k in d.get("keys", []) if k != kid})
    for other in old:
        if _change(args, {"op": "retire", "key_id": other}):
            raise SdrpeerError(f"rotation stopped at retire {other}: see above")
    return 0


def add_key_parsers(
    sub: argparse._SubParsersAction[argparse.ArgumentParser],
    client: argparse.ArgumentParser,
    as_json: argparse.ArgumentParser,
) -> None:
    """`sdrpeer keygen` and `sdrpeer key ...`."""
    keygen = sub.add_parser(
        "keygen", help="print a new cluster key", description=cmd_keygen.__doc__
    )
    keygen.set_defaults(func=cmd_keygen)
    key = sub.add_parser(
        "key",
        help="rotate the cluster key of a running fleet",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    key_sub = key.add_subparsers(dest="key_command", required=True, metavar="ACTION")
    listing = key_sub.add_parser("list", parents=[client, as_json], help="every robot's keys")
    listing.set_defaults(func=cmd_key_list)
    add = key_sub.add_parser("add", parents=[client, as_json], help="install a key everywhere")
    add.add_argument("key_file", metavar="KEYFILE", help="file holding the key (- for stdin)")
    add.set_defaults(func=cmd_key_add)
    for name, func, text in (
        ("primary", cmd_key_primary, "seal with this key everywhere"),
        ("retire", cmd_key_retire, "remove this key everywhere"),
    ):
        p = key_sub.add_parser(name, parents=[client, as_json], help=text)
        p.add_argument("key", metavar="KEY", help="key id (8 hex digits, see key list) or key file")
        p.set_defaults(func=func)
    rotate = key_sub.add_parser(
        "rotate", parents=[client, as_json], help="add, make primary, retire the others"
    )
    rotate.add_argument(
        "key_file", metavar="KEYFILE", help="file holding the new key (- for stdin)"
    )
    rotate.set_defaults(func=cmd_key_rotate)
