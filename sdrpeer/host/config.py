"""A host's configuration: from its command line and the SDRPEER_* environment the agent sets
(docs/protocol.md), and its fixed timings."""

from __future__ import annotations

import argparse
from dataclasses import dataclass, field

from sdrpeer.keys.datakeys import ENV as DATA_KEYS_ENV
from sdrpeer.keys.datakeys import keys_from_env

FINALIZE_TIMEOUT = 5.0
"""Seconds `on_deactivated` + `on_finalize` may take when no `exit` timeout was given."""
STANDALONE_REPORT_INTERVAL = 1.0
"""Seconds between two counter lines in standalone mode."""


@dataclass(frozen=True)
class HostConfig:
    """Everything a host needs to start, from its command line and environment."""

    target: str
    """`pkg.mod:Class` or `path/to/file.py[:Class]`, or with `composite` a composite's target."""
    composite: bool = False
    """`--composite`: the target is `CONTEXT;Member=pkg.mod:Class;...`
    (sdrpeer.launch.composite)."""
    params: dict[str, str] = field(default_factory=dict)
    """Initial parameter values as given on the command line."""
    name: str = ""
    """The instance name (`--name`, else `SDRPEER_INSTANCE`, else the class name)."""
    control_fd: int | None = None
    """The inherited control socket (`SDRPEER_CONTROL_FD`), None when standalone."""
    data_host: str = "127.0.0.1"
    """Where the data server listens for TCP (`SDRPEER_DATA_HOST`)."""
    run_dir: str | None = None
    """Directory for the Unix data socket (`SDRPEER_RUN_DIR`), None for a temporary one."""
    data_keys: tuple[bytes, ...] = ()
    """Keys data connections are authenticated with (`SDRPEER_DATA_KEYS`); none: open."""


def parse_args(argv: list[str], env: dict[str, str]) -> HostConfig:
    """Build a HostConfig from argv and the environment (SystemExit(2) on a bad command line)."""
    parser = argparse.ArgumentParser(
        prog="python -m sdrpeer.host", description="Run one component instance."
    )
    parser.add_argument("target", help="pkg.module:Class or path/to/file.py[:Class]")
    parser.add_argument("--param", action="append", default=[], metavar="K=V")
    parser.add_argument("--name", default="")
    parser.add_argument(
        "--composite",
        action="store_true",
        help="the target is a composite: 'periodic:HZ|stepped;Member=pkg.mod:Class;...'",
    )
    args = parser.parse_args(argv)
    params: dict[str, str] = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep or not key:
            parser.error(f"--param {item!r}: expected NAME=VALUE")
        params[key] = value
    fd_text = env.get("SDRPEER_CONTROL_FD")
    control_fd = None
    if fd_text:
        try:
            control_fd = int(fd_text)
        except ValueError:
            parser.error(f"SDRPEER_CONTROL_FD={fd_text!r} is not a file descriptor number")
    try:
        data_keys = tuple(keys_from_env(env.get(DATA_KEYS_ENV)))
    except ValueError as exc:
        parser.error(str(exc))
    return HostConfig(
        data_keys=data_keys,
        target=args.target,
        composite=args.composite,
        params=params,
        name=args.name or env.get("SDRPEER_INSTANCE", ""),
        control_fd=control_fd,
        data_host=env.get("SDRPEER_DATA_HOST") or "127.0.0.1",
        run_dir=env.get("SDRPEER_RUN_DIR") or None,
    )
