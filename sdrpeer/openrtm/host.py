"""The openrtm host's main: the RTC created, its Component built, the control channel served.

How it works: the command line and environment are the Python host's (sdrpeer.host.config); the
target is an RTC module (`path/to/Module.py[:TypeName]` or `pkg.module[:TypeName]`), each
`--param` a configuration parameter of the RTC (`conf.default.NAME`). Exit codes as the Python
host's: 2 when OpenRTM is missing or the RTC cannot be loaded or created.
"""

from __future__ import annotations

import asyncio
import os
import shutil
import sys
import traceback

from sdrpeer.control.host_side import arm_parent_death_signal
from sdrpeer.errors import LoadError, SdrpeerError
from sdrpeer.host.config import parse_args
from sdrpeer.host.main import setup_logging
from sdrpeer.launch.openrtm import available


def main(argv: list[str] | None = None) -> int:
    """Run an RTC under an agent (or standalone); returns the exit code."""
    config = parse_args(sys.argv[1:] if argv is None else argv, dict(os.environ))
    if config.control_fd is not None:
        arm_parent_death_signal()
    setup_logging(config.name or config.target)
    missing = available()
    if missing is not None:
        print(f"sdrpeer.openrtm: {missing}", file=sys.stderr)
        return 2
    from sdrpeer.host.serve import Host  # noqa: PLC0415 - after logging, so import errors show
    from sdrpeer.openrtm.component import component_class  # noqa: PLC0415
    from sdrpeer.openrtm.runtime import RtcRuntime, start_manager  # noqa: PLC0415

    manager = start_manager()
    try:
        runtime = RtcRuntime(manager, config.target, dict(config.params))
        cls = component_class(runtime)
        component = cls(name=config.name or runtime.type_name, params=config.params)
    except (LoadError, SdrpeerError) as exc:
        print(f"sdrpeer.openrtm: cannot load {exc}", file=sys.stderr)
        if exc.__cause__ is not None:
            traceback.print_exception(exc.__cause__, file=sys.stderr)
        manager.shutdown()
        return 2
    host = Host(config, component)
    try:
        return asyncio.run(host.run())
    except KeyboardInterrupt:
        return 1
    finally:
        if host.tmp_dir is not None:
            shutil.rmtree(host.tmp_dir, ignore_errors=True)
