"""`python -m sdrpeer.host TARGET [--param k=v ...] [--name NAME]`: run one component instance.

How it works: the target is loaded (`loader`), the instance and its `ComponentRunner` created with
the `--param` values (strings; the SDK converts them to each param's type), and a `DataServer`
started (TCP on `SDRPEER_DATA_HOST` or 127.0.0.1, a Unix socket in `SDRPEER_RUN_DIR` or a temporary
directory). Under an agent (`SDRPEER_CONTROL_FD` set) the host sends `hello`, initializes
(-> `state INACTIVE`) and serves commands one at a time, in order, until `exit`, SIGTERM, or the
end of the control channel (the agent died); then it finalizes and exits. Standalone it activates
at once, logs state changes and, once a second, the port counters, and exits on SIGINT/SIGTERM.
With `--composite` the target is a composite's (sdrpeer.launch.composite): every member class is
loaded and the host runs them as one component (sdrpeer.sdk.composite), params `Member.param`.
Exit codes: 0 after a clean finalize, 1 if finalizing failed or timed out, 2 if the target could
not be loaded or the command line is wrong. Everything is logged to stderr.
"""

from __future__ import annotations

import asyncio
import logging
import os
import shutil
import sys
from collections.abc import Callable

from sdrpeer.control.host_side import arm_parent_death_signal
from sdrpeer.errors import LoadError, SdrpeerError
from sdrpeer.host.config import HostConfig, parse_args
from sdrpeer.host.loader import load_component_class, load_composite_class

log = logging.getLogger("sdrpeer.host")


def setup_logging(name: str) -> None:
    """Plain lines on stderr (the agent sends them to the instance's log file)."""
    handler = logging.StreamHandler(sys.stderr)
    handler.setFormatter(
        logging.Formatter(f"%(asctime)s %(levelname)-7s {name} %(name)s: %(message)s")
    )
    root = logging.getLogger()
    root.handlers[:] = [handler]
    root.setLevel(logging.INFO)


def load_class(config: HostConfig) -> type:
    """The component class a host runs (LoadError if it cannot be loaded)."""
    from sdrpeer.sdk import Component  # noqa: PLC0415 - after logging, so import errors show

    if config.composite:
        return load_composite_class(config.name or "Composite", config.target)
    return load_component_class(config.target, Component)


def main(argv: list[str] | None = None, *, load: Callable[[HostConfig], type] = load_class) -> int:
    """Run a host; returns the exit code. `load` finds the class (a ROS 2 host wraps a node
    class: sdrpeer.ros2.host)."""
    config = parse_args(sys.argv[1:] if argv is None else argv, dict(os.environ))
    if config.control_fd is not None:
        arm_parent_death_signal()
    setup_logging(config.name or ("composite" if config.composite else config.target))
    try:
        cls = load(config)
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
