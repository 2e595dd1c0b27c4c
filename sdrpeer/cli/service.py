"""`sdrpeer systemd-unit`: the systemd service unit that runs a robot's agent, written for this
installation (its Python, the config file, the user and the data directory).

How it works: `unit_text` fills a fixed template: `ExecStart` runs this interpreter's
`-m sdrpeer agent --config FILE --data-dir DIR` (so the unit starts the installation that wrote
it, a venv included), `ExecReload` sends SIGHUP (the agent reads its keys again), SIGTERM stops
it gracefully (it leaves the fleet and stops its component hosts; `KillMode=mixed` SIGKILLs
what is left after `TimeoutStopSec`), `Restart=on-failure` brings it back. The unit runs as an
unprivileged user with the data directory as its systemd `StateDirectory` when it lies under
/var/lib, and with `NoNewPrivileges`, `PrivateTmp` and `ProtectSystem=full`. `-o FILE` writes
it (e.g. /etc/systemd/system/sdrpeer.service); `systemd-analyze verify` accepts it (a test
checks that).
"""

from __future__ import annotations

import argparse
import re
import sys
from pathlib import Path

DEFAULT_CONFIG = Path("/etc/sdrpeer/agent.yaml")
DEFAULT_DATA_DIR = Path("/var/lib/sdrpeer")
DEFAULT_USER = "sdrpeer"
STOP_TIMEOUT_S = 20
_USER = re.compile(r"[a-z_][a-z0-9_-]{0,31}")


def _quote(arg: str) -> str:
    """One ExecStart argument, quoted for systemd when it needs to be."""
    if arg and not re.search(r"[\s\"'\\$%;]", arg):
        return arg
    escaped = arg.replace("\\", "\\\\").replace('"', '\\"').replace("$", "$$").replace("%", "%%")
    return f'"{escaped}"'


def unit_text(
    config: Path,
    *,
    user: str = DEFAULT_USER,
    data_dir: Path = DEFAULT_DATA_DIR,
    python: str = sys.executable,
) -> str:
    """The unit file's text; ValueError for a user name or a path systemd would refuse."""
    if not _USER.fullmatch(user):
        raise ValueError(f"--user {user!r}: not a user name systemd accepts")
    for flag, path in (("--config", config), ("--data-dir", data_dir), ("python", Path(python))):
        if not path.is_absolute():
            raise ValueError(f"{flag} {path}: systemd needs an absolute path")
    command = [
        python,
        "-m",
        "sdrpeer",
        "agent",
        "--config",
        str(config),
        "--data-dir",
        str(data_dir),
    ]
    state = ""
    var_lib = Path("/var/lib")
    if data_dir.parent == var_lib:
        state = f"StateDirectory={data_dir.name}\nStateDirectoryMode=0700\n"
    else:
        state = f"ReadWritePaths={_quote(str(data_dir))}\n"
    return f"""\
# sdrpeer agent: written by `sdrpeer systemd-unit` (docs/deploy.md).
# Install: sudo cp THIS /etc/systemd/system/sdrpeer.service
#          sudo systemctl daemon-reload && sudo systemctl enable --now sdrpeer
[Unit]
Description=sdrpeer agent (software-defined robot peer)
Wants=network-online.target
After=network-online.target

[Service]
Type=exec
User={user}
Group={user}
ExecStart={" ".join(_quote(a) for a in command)}
ExecReload=/bin/kill -HUP $MAINPID
KillSignal=SIGTERM
KillMode=mixed
TimeoutStopSec={STOP_TIMEOUT_S}
Restart=on-failure
RestartSec=2
{state}NoNewPrivileges=yes
PrivateTmp=yes
ProtectSystem=full
LimitNOFILE=65536

[Install]
WantedBy=multi-user.target
"""


def cmd_systemd_unit(args: argparse.Namespace) -> int:
    """Print (or write with -o) the agent's systemd unit."""
    try:
        text = unit_text(args.config, user=args.user, data_dir=args.data_dir, python=args.python)
    except ValueError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    if args.output is None:
        sys.stdout.write(text)
    else:
        args.output.write_text(text)
        print(f"wrote {args.output}", file=sys.stderr)
    return 0


def add_service_parser(sub: argparse._SubParsersAction[argparse.ArgumentParser]) -> None:
    """`sdrpeer systemd-unit`."""
    p = sub.add_parser(
        "systemd-unit",
        help="write the systemd unit that runs this robot's agent",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument(
        "--config",
        type=Path,
        default=DEFAULT_CONFIG,
        metavar="FILE",
        help=f"the agent config file (default {DEFAULT_CONFIG})",
    )
    p.add_argument("--user", default=DEFAULT_USER, help=f"run as (default {DEFAULT_USER})")
    p.add_argument(
        "--data-dir",
        type=Path,
        default=DEFAULT_DATA_DIR,
        metavar="DIR",
        help=f"the agent's data directory (default {DEFAULT_DATA_DIR})",
    )
    p.add_argument(
        "--python",
        default=sys.executable,
        metavar="PATH",
        help="the interpreter with sdrpeer installed (default: this one)",
    )
    p.add_argument("-o", "--output", type=Path, metavar="FILE", help="write here, not to stdout")
    p.set_defaults(func=cmd_systemd_unit)
