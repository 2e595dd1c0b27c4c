"""`python -m sdrpeer.host TARGET [--param k=v ...] [--name NAME]`: run one component instance.

How it works: the target is loaded (`loader`), the instance and its `ComponentRunner` created with
the `--param` values (strings; the SDK converts them to each param's type), and a `DataServer`
started (TCP on `SDRPEER_DATA_HOST` or 127.0.0.1, a Unix socket in `SDRPEER_RUN_DIR` or a temporary
directory). Under an agent (`SDRPEER_CONTROL_FD` set) the host sends `hello`, initializes
(-> `state INACTIVE`) and serves commands one at a time, in order, until `exit`, SIGTERM, or the
end of the control channel (the agent died); then it finalizes and exits. Standalone it activates
at once, logs state changes and, once a second, the port counters, and exits on SIGINT/SIGTERM.
Exit codes: 0 after a clean finalize, 1 if finalizing failed or timed out, 2 if the target could
not be loaded or the command line is wrong. Everything is logged to stderr.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import os
import shutil
import signal
import sys
import time
from dataclasses import dataclass, field

from sdrpeer.datakeys import ENV as DATA_KEYS_ENV
from sdrpeer.datakeys import keys_from_env
from sdrpeer.errors import SdrpeerError
from sdrpeer.host import control
from sdrpeer.host.loader import LoadError, load_component_class

log = logging.getLogger("sdrpeer.host")

FINALIZE_TIMEOUT = 5.0
"""Seconds `on_deactivated` + `on_finalize` may take when no `exit` timeout was given."""
STANDALONE_REPORT_INTERVAL = 1.0
"""Seconds between two counter lines in standalone mode."""


@dataclass(frozen=True)
class HostConfig:
    """Everything a host needs to start, from its command line and environment."""

    target: str
    """`pkg.mod:Class` or `path/to/file.py[:Class]`."""
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
    parser = argparse.ArgumentParser(prog="python -m sdrpeer.host", description=__doc__)
    parser.add_argument("target", help="pkg.module:Class or path/to/file.py[:Class]")
    parser.add_argument("--param", action="append", default=[], metavar="K=V")
    parser.add_argument("--name", default="")
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
        params=params,
        name=args.name or env.get("SDRPEER_INSTANCE", ""),
        control_fd=control_fd,
        data_host=env.get("SDRPEER_DATA_HOST") or "127.0.0.1",
        run_dir=env.get("SDRPEER_RUN_DIR") or None,
    )


def setup_logging(name: str) -> None:
    """Plain lines on stderr (the agent sends them to the instance's log file)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(
        logging.Formatter(f"%(asctime)s %(levelname)-7s {name} %(name)s: %(message)s")
    )
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(logging.INFO)


def main(argv: list[str] | None = None) -> int:
    """Run a host; returns the exit code."""
    config = parse_args(sys.argv[1:] if argv is None else argv, dict(os.environ))
    if config.control_fd is not None:
        control.arm_parent_death_signal()
    setup_logging(config.name or config.target)
    from sdrpeer.sdk import Component  # noqa: PLC0415 - after logging, so import errors show

    try:
        cls = load_component_class(config.target, Component)
    except LoadError as exc:
        print(f"sdrpeer.host: cannot load {exc}", file=sys.stderr)
        if exc.__cause__ is not None:
            import traceback  # noqa: PLC0415 - only on this error path

            traceback.print_exception(exc.__cause__, file=sys.stderr)
        return 2
    try:
        component = cls(name=config.name or cls.__name__, params=config.params)
    except SdrpeerError as exc:
        print(f"sdrpeer.host: {config.target}: {exc}", file=sys.stderr)
        return 2
    except Exception:
        log.exception("%s: %s() raised", config.target, cls.__name__)
        return 2
    from sdrpeer.host.serve import Host  # noqa: PLC0415 - needs the SDK and data plane

    host = Host(config, component)
    try:
        return asyncio.run(host.run())
    except KeyboardInterrupt:  # a second Ctrl-C while finalizing
        return 1
    finally:
        if host.tmp_dir is not None:
            shutil.rmtree(host.tmp_dir, ignore_errors=True)


def install_signals(loop: asyncio.AbstractEventLoop, stop: asyncio.Event) -> None:
    """SIGTERM/SIGINT ask for a clean exit; a second one forces it (signal handlers only queue)."""

    def on_signal(signum: int) -> None:
        if stop.is_set():
            log.warning("second %s: exiting now", signal.Signals(signum).name)
            os._exit(1)
        log.info("%s: finalizing", signal.Signals(signum).name)
        stop.set()

    for sig in (signal.SIGTERM, signal.SIGINT):
        loop.add_signal_handler(sig, on_signal, sig)


def now() -> float:
    """Unix seconds, for reports."""
    return time.time()
