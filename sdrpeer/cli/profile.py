"""`sdrpeer profile TARGET`: the command line of `sdrpeer.profiling.measure`."""

from __future__ import annotations

import argparse
from pathlib import Path

from sdrpeer.errors import ConfigError
from sdrpeer.profiling.inputs import GENERATORS


def _pairs(items: list[str], flag: str) -> dict[str, str]:
    out: dict[str, str] = {}
    for item in items:
        key, sep, value = item.partition("=")
        if not sep or not key:
            raise ConfigError(f"{flag} {item!r}: expected NAME=VALUE")
        out[key] = value
    return out


def add_profile_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`sdrpeer profile TARGET [--seconds N] [--param k=v] [--input port=gen] [--out FILE]`."""
    p = sub.add_parser("profile", help="measure a component's CPU, memory and port rates")
    p.add_argument("target", help="package.module:Class")
    p.add_argument("--seconds", type=float, default=10.0, help="measured window (default 10)")
    p.add_argument("--param", action="append", default=[], metavar="K=V", help="a param")
    p.add_argument(
        "--input",
        action="append",
        default=[],
        metavar="PORT=GEN",
        help=f"feed an in-port from a generator ({', '.join(GENERATORS)}, image:WxH) or a "
        "msgpack file",
    )
    p.add_argument("--input-rate", type=float, default=10.0, help="Hz per in-port (default 10)")
    p.add_argument("--out", type=Path, help="write the YAML here (also printed)")
    p.set_defaults(func=cmd_profile)


def cmd_profile(args: argparse.Namespace) -> int:
    """Run `sdrpeer profile`."""
    import asyncio  # noqa: PLC0415 - the profiler runs a host: only this command loads it

    from sdrpeer.profiling.measure import (  # noqa: PLC0415
        ProfileRequest,
        run_profile,
        write_profile,
    )

    req = ProfileRequest(
        target=args.target,
        seconds=args.seconds,
        params=_pairs(args.param, "--param"),
        inputs=_pairs(args.input, "--input"),
        input_rate=args.input_rate,
    )
    profile = asyncio.run(run_profile(req))
    print(write_profile(profile, args.out), end="")
    return 0
