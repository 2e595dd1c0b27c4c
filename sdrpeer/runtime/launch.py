"""Starting one host process: its argv, its environment, its log file, and dying with the agent.

How it works: `host_argv(spec)` asks the spec's launcher (`sdrpeer.launch.launchers`: python,
script,
exec, or a plugin) for the command; `host_env` adds the SDRPEER_* variables of docs/protocol.md
(and SDRPEER_PARAMS for exec hosts) to the agent's environment.
`open_log` appends a start banner to `DATA_DIR/instances/NAME.log` and returns the file the host's
stdout and stderr go to. `die_with_parent` runs in the child between fork and exec: on Linux it
asks the kernel to SIGKILL the host when the agent dies (prctl PR_SET_PDEATHSIG), so a crashed
or killed agent leaves no orphan hosts behind. `create_process` starts one so that a cancelled
caller cannot orphan it. `wait_exit` and `exit_text` help stopping one.
"""

from __future__ import annotations

import asyncio
import contextlib
import ctypes
import ctypes.util
import os
import shlex
import signal
import sys
import tempfile
import time
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import IO, Any

from sdrpeer.keys.datakeys import ENV as DATA_KEYS_ENV
from sdrpeer.keys.datakeys import keys_to_env
from sdrpeer.launch import launchers
from sdrpeer.launch.launchers import get_launcher
from sdrpeer.runtime.spec import InstanceSpec

_PR_SET_PDEATHSIG = 1
_SIGKILL = 9


def host_argv(spec: InstanceSpec) -> list[str]:
    """The command that starts the host of `spec` (launcher plugins: sdrpeer.launch.launchers)."""
    target = list(spec.target) if isinstance(spec.target, tuple) else spec.target
    launcher = get_launcher(spec.launcher)
    return launcher.command(target, spec.params_map(), python=sys.executable)


def host_env(
    base: Mapping[str, str],
    spec: InstanceSpec,
    *,
    fd: int,
    data_host: str,
    run_dir: Path,
    data_keys: Sequence[bytes] = (),
) -> dict[str, str]:
    """The host's environment: the agent's plus the control channel variables (and params),
    and the data keys its connections authenticate with (none: SDRPEER_DATA_KEYS unset)."""
    env = dict(base)
    env.pop("SDRPEER_PARAMS", None)
    env.pop(DATA_KEYS_ENV, None)
    if data_keys:
        env[DATA_KEYS_ENV] = keys_to_env(data_keys)
    env.update(
        launchers.host_env(
            instance=spec.name,
            control_fd=fd,
            data_host=data_host,
            run_dir=str(run_dir),
            params=spec.params_map(),
        )
    )
    return env


def log_path(data_dir: Path, name: str) -> Path:
    """Where the host of instance `name` writes its output."""
    return data_dir / "instances" / f"{name}.log"


def open_log(data_dir: Path, name: str, argv: list[str]) -> IO[bytes]:
    """Open the instance log for appending, after writing a start banner."""
    path = log_path(data_dir, name)
    path.parent.mkdir(parents=True, exist_ok=True)
    f = path.open("ab")
    stamp = time.strftime("%Y-%m-%d %H:%M:%S")
    f.write(f"==== {stamp} sdrpeer: starting {name}: {shlex.join(argv)}\n".encode())
    f.flush()
    return f


def _load_prctl() -> Callable[..., int] | None:
    if not sys.platform.startswith("linux"):
        return None
    name = ctypes.util.find_library("c")
    try:
        fn: Callable[..., int] = ctypes.CDLL(name, use_errno=True).prctl
    except (OSError, AttributeError):
        return None
    return fn


_PRCTL = _load_prctl()  # looked up in the parent: the child only calls it


def die_with_parent() -> None:
    """In the child before exec: be SIGKILLed when the agent (our parent thread) dies."""
    if _PRCTL is not None:
        _PRCTL(_PR_SET_PDEATHSIG, _SIGKILL)


def preexec(nice: int = 0) -> Callable[[], None] | None:
    """The preexec_fn for hosts: die with the agent where there is a parent-death signal, and
    run `nice` steps nicer than the agent (None: nothing to do in the child)."""
    if nice <= 0:
        return die_with_parent if _PRCTL is not None else None

    def child() -> None:
        die_with_parent()
        with contextlib.suppress(OSError):
            os.nice(nice)

    return child


async def create_process(argv: list[str], **options: Any) -> asyncio.subprocess.Process:
    """`asyncio.create_subprocess_exec(*argv, **options)`, safe to cancel: the fork happens before
    that call returns, so a caller cancelled meanwhile would leave a process nobody knows; here
    the creation finishes anyway and that process is killed and reaped before the cancel goes on.
    """
    creating = asyncio.ensure_future(asyncio.create_subprocess_exec(*argv, **options))
    try:
        return await asyncio.shield(creating)
    except asyncio.CancelledError:
        with contextlib.suppress(Exception):
            orphan = await creating
            orphan.kill()
            await orphan.wait()
        raise


def _private_base() -> str:
    base = os.environ.get("XDG_RUNTIME_DIR") or tempfile.gettempdir()
    return base if len(base) <= 60 else tempfile.gettempdir()


def private_dir(prefix: str) -> Path:
    """A fresh 0700 directory for a host's Unix socket, short enough for sun_path (108 bytes)."""
    return Path(tempfile.mkdtemp(prefix=f"sdrp-{prefix[:24]}-", dir=_private_base()))


def listening_unix_paths(table: str = "/proc/net/unix") -> set[str] | None:
    """The paths of every Unix socket bound on this machine now (None where the kernel's table
    cannot be read: then nothing can be called stale)."""
    try:
        with open(table, encoding="utf-8", errors="replace") as f:
            next(f, None)  # the header
            return {fields[7] for line in f if len(fields := line.split()) >= 8}
    except OSError:
        return None


def sweep_private_dirs(now: float, min_age: float = 60.0, base: str | None = None) -> int:
    """Remove the host directories of hosts that died without their agent cleaning up (a
    SIGKILLed agent leaves them): `sdrp-*` directories older than `min_age` seconds in which no
    socket is bound any more. Agents share the base directory, so another agent's live host is
    kept by its bound socket, and one starting now by its age. How many were removed."""
    bound = listening_unix_paths()
    if bound is None:
        return 0
    removed = 0
    root = Path(base or _private_base())
    for path in root.glob("sdrp-*"):
        try:
            if not path.is_dir() or path.is_symlink() or now - path.stat().st_mtime < min_age:
                continue
            if any(str(child) in bound for child in path.iterdir()):
                continue
        except OSError:
            continue
        remove_dir(path)
        removed += not path.exists()
    return removed


def remove_dir(path: Path) -> None:
    """Remove a host's private directory and what it left in it (best effort: one already gone,
    another agent's sweep being first, is no error)."""
    try:
        children = list(path.iterdir())
    except OSError:
        return
    for child in children:
        with contextlib.suppress(OSError):
            child.unlink()
    with contextlib.suppress(OSError):
        path.rmdir()


def exit_text(rc: int | None) -> str:
    """'exited with code 3' or 'killed by SIGKILL'."""
    if rc is None:
        return "did not start"
    if rc < 0:
        with contextlib.suppress(ValueError):
            return f"killed by {signal.Signals(-rc).name}"
    return f"exited with code {rc}"


async def wait_exit(proc: asyncio.subprocess.Process, seconds: float) -> bool:
    """Whether the process exited within `seconds`."""
    try:
        async with asyncio.timeout(max(0.0, seconds)):  # wait_for can swallow a cancel (3.11)
            await proc.wait()
    except TimeoutError:
        return False
    return True
