"""`sdrpeer system check FILE` and `sdrpeer system schema`.

How it works: `check` loads the file exactly as `sdrpeer deploy` would (nothing is sent anywhere;
each `python` component's module is imported to check its ports and params, which runs the module's
top-level code) and prints what it understood: each component with its needs and standbys, each
connection with its expected traffic, and the allocation thresholds; every problem is reported with
file:line and the command exits 2. `schema` prints the JSON Schema for editors (or its path).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from sdrpeer.units import format_size


def add_system_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """Register `sdrpeer system check|schema`."""
    p = sub.add_parser("system", help="check a system file, print the schema")
    ssub = p.add_subparsers(dest="system_command", required=True, metavar="ACTION")
    check = ssub.add_parser(
        "check",
        help="validate a system file (nothing is deployed)",
        description="Validate a system file: nothing is deployed, but each python component's"
        " module is imported (its top-level code runs) to check its ports and params.",
    )
    check.add_argument("file", type=Path)
    check.add_argument("--json", action="store_true", help="print the loaded system as JSON")
    check.set_defaults(func=cmd_check)
    schema = ssub.add_parser("schema", help="print the JSON Schema of system files")
    schema.add_argument("--path", action="store_true", help="print only the schema file's path")
    schema.set_defaults(func=cmd_schema)


def cmd_check(args: argparse.Namespace) -> int:
    """Load and summarise a system file."""
    from sdrpeer.launch.composite import parse_composite  # noqa: PLC0415 - with the loader
    from sdrpeer.system.loader import load_system  # noqa: PLC0415 - imports plugins

    system = load_system(args.file)
    if args.json:
        print(json.dumps(system.to_json(), indent=2, default=str))
        return 0
    print(f"{args.file}: system {system.name!r} is valid (digest {system.digest()})")
    for c in system.components:
        r = c.requires
        standby = ""
        if c.standby.same_robot or c.standby.other_robots:
            standby = (
                f", standbys {c.standby.same_robot} same / {c.standby.other_robots} other"
                f" ({c.standby.mode})"
            )
        print(
            f"  {c.name:<28} cpu {r.cpu_pct:5.1f}%  memory {format_size(r.mem_bytes):>8}{standby}"
        )
        if c.launcher == "composite" and isinstance(c.target, str):
            target = parse_composite(c.target)
            context = "stepped" if target.hz is None else f"periodic {target.hz:g} Hz"
            members = ", ".join(m for m, _ in target.members)
            print(f"  {'':<28} composite, {context}: {members}")
        own = {k: v for k, v in vars_of(c.thresholds).items() if v is not None}
        if own:
            print(f"  {'':<28} own thresholds {own}")
    for conn in system.connections:
        rate = conn.traffic_bytes_per_s
        traffic = "?" if rate is None else f"{format_size(int(rate))}/s"
        bounds = {k: v for k, v in vars_of(conn.bounds).items() if v is not None}
        print(f"  {conn.id:<60} {traffic}" + (f"  own bounds {bounds}" if bounds else ""))
    a = system.allocation
    limits = {k: v for k, v in vars_of(a.thresholds).items() if v is not None}
    print(f"  allocation: {a.strategy}, thresholds {limits or 'none'}")
    print(f"  recovery: {len(system.recovery.rules)} rules")
    k = system.compliance
    print(
        f"  compliance: {k.on_violation} after {k.sustain_s:g}s, clears {k.clear:.0%} inside, "
        f"at most one move per {k.min_interval_s:g}s"
    )
    return 0


def vars_of(obj: object) -> dict[str, object]:
    """Fields of a slotted dataclass as a dict."""
    return {name: getattr(obj, name) for name in getattr(obj, "__slots__", ())}


def cmd_schema(args: argparse.Namespace) -> int:
    """Print the schema (or where it is)."""
    from sdrpeer.system.loader import schema_path  # noqa: PLC0415

    path = schema_path()
    print(path if args.path else path.read_text().rstrip())
    return 0
