"""The lab's processes: how its agents are marked, found again and stopped (`sdrpeer lab down`).

How it works: every agent a lab starts carries the lab in its environment (`SDRPEER_LAB=<the lab
directory, resolved>`, inherited by its component hosts) and is recorded in lab.json the moment
it is spawned: its pid and its start time (`started`, as psutil reads it), so a pid the system
gave to another process since is never signalled. An agent can still escape the record: the
`lab up` command may die between spawning it and writing lab.json (a SIGKILL, a crash, a loaded
machine stretching that moment). So stopping a lab does not trust lab.json alone: `lab_processes`
also scans every process for the lab's marker, and for an `sdrpeer agent` whose `--data-dir` lies
in the lab directory (an agent started by an older lab, without the marker). Whatever is found is
sent SIGTERM; what has not exited `grace` s later is SIGKILLed with its process group (an agent
leads its own session: its component hosts are in it).

While `lab up` starts agents it holds the lab's lock (`lab.lock`, an flock: released by the
kernel if the command dies); `lab down` takes it before it looks, so no agent is spawned after
the scan. Reading /proc needs psutil, which the client commands do without: it is imported here
only.
"""

from __future__ import annotations

import contextlib
import fcntl
import itertools
import os
import re
import signal
import time
from collections.abc import Iterator, Mapping
from dataclasses import asdict
from pathlib import Path
from typing import TYPE_CHECKING, Any

from sdrpeer.errors import SdrpeerError
from sdrpeer.lab.files import LAB_FILE, Lab, LabRobot, lab_path, read_lab

if TYPE_CHECKING:
    import psutil

LAB_ENV = "SDRPEER_LAB"
"""The environment variable that marks a process as the lab's: the lab directory, resolved."""
LOCK_FILE = "lab.lock"
LOCK_POLL = 0.1
LOCK_WAIT = 60.0
"""How long `lab down` waits for a `lab up` that is starting agents to be done (s)."""
STARTED_SLACK = 1.0
"""Seconds a recorded start time may differ from the one read again: /proc counts clock ticks
from boot, and psutil adds the boot time, which moves when the wall clock is stepped. A reused
pid must also run `sdrpeer agent` with the same --data-dir to pass, so this needs no precision."""


def lab_mark(lab_dir: Path) -> str:
    """The marker value of the lab in `lab_dir` (its resolved path)."""
    return os.path.realpath(lab_dir)


def lab_env(lab_dir: Path, base: Mapping[str, str]) -> dict[str, str]:
    """`base` plus the marker of the lab in `lab_dir`."""
    env = dict(base)
    env[LAB_ENV] = lab_mark(lab_dir)
    return env


def start_time(pid: int) -> float | None:
    """When process `pid` started (psutil's create_time), None if it is gone."""
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    try:
        return float(psutil.Process(pid).create_time())
    except psutil.Error:
        return None


@contextlib.contextmanager
def lab_lock(lab_dir: Path, timeout: float | None = None) -> Iterator[bool]:
    """Hold the lab's lock; yields False when `timeout` s passed without it (then nothing is
    held). None: wait as long as it takes."""
    lab_dir.mkdir(parents=True, exist_ok=True)
    fd = os.open(lab_dir / LOCK_FILE, os.O_RDWR | os.O_CREAT, 0o600)
    try:
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
                break
            except BlockingIOError:
                if deadline is not None and time.monotonic() >= deadline:
                    yield False
                    return
                time.sleep(LOCK_POLL)
        yield True
    finally:
        os.close(fd)  # closing the descriptor releases the lock


def is_agent_command(cmdline: list[str]) -> bool:
    """Whether a command line runs `sdrpeer agent` (`python -m sdrpeer agent`, `sdrpeer agent`)."""
    return any(a.endswith("sdrpeer") and b == "agent" for a, b in itertools.pairwise(cmdline))


def _data_dirs(cmdline: list[str]) -> list[str]:
    """The `--data-dir` values of a command line, resolved."""
    dirs = [b for a, b in itertools.pairwise(cmdline) if a == "--data-dir"]
    dirs += [a.removeprefix("--data-dir=") for a in cmdline if a.startswith("--data-dir=")]
    return [os.path.realpath(d) for d in dirs]


def is_agent_process(pid: int, robot: LabRobot) -> bool:
    """True if `pid` runs `sdrpeer agent` for this robot (same --data-dir) and, when lab.json
    recorded it, started when the recorded one did (not a reused pid); False otherwise."""
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    try:
        proc = psutil.Process(pid)
        if proc.status() == psutil.STATUS_ZOMBIE:
            return False
        cmdline = proc.cmdline()
        started = proc.create_time()
    except psutil.Error:
        return False
    if robot.started is not None and abs(started - robot.started) > STARTED_SLACK:
        return False
    return is_agent_command(cmdline) and os.path.realpath(robot.data_dir) in _data_dirs(cmdline)


def running_pids(lab: Lab) -> dict[str, int]:
    """Robot name -> pid for every robot whose recorded pid still is its agent."""
    return {r.name: r.pid for r in lab.robots if r.pid is not None and is_agent_process(r.pid, r)}


def lab_processes(lab_dir: Path) -> list[psutil.Process]:
    """Every live process of the lab in `lab_dir` (this one excepted) whose parent is not one:
    those carrying its marker, and `sdrpeer agent`s whose --data-dir is inside it. (A component
    host carries its agent's marker: it is stopped by its agent, or killed with its group.)"""
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    mark = lab_mark(lab_dir)
    inside = mark.rstrip("/") + "/"
    found = []
    for proc in psutil.process_iter():
        if proc.pid == os.getpid():
            continue
        try:
            if proc.status() == psutil.STATUS_ZOMBIE:
                continue
            cmdline = proc.cmdline()
            ours = is_agent_command(cmdline) and any(
                d.startswith(inside) for d in _data_dirs(cmdline)
            )
            if not ours:
                ours = proc.environ().get(LAB_ENV) == mark
        except psutil.Error:
            continue
        if ours:
            found.append(proc)
    pids = {p.pid for p in found}
    return [p for p in found if _parent(p) not in pids]  # a host goes with its agent


def _parent(proc: psutil.Process) -> int | None:
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    try:
        return int(proc.ppid())
    except psutil.Error:
        return None


def processes_naming(path: Path) -> list[str]:
    """Every live process (this one excepted) whose command line or environment names `path`
    or a path inside it, one line each (its pid and command line). Read from /proc, whatever the
    lab records or marks: the check that a lab left nothing behind (tests, tools/bench_lab_down.py),
    independent of `lab_processes`, the scan `lab down` relies on."""
    mark = os.path.realpath(path).encode()
    names_it = re.compile(re.escape(mark) + rb"(?:/|\x00|$)")
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit() or int(entry.name) == os.getpid():
            continue
        try:
            cmdline = (entry / "cmdline").read_bytes()
            environ = (entry / "environ").read_bytes()
            state = (entry / "stat").read_bytes().rpartition(b")")[2].split()[0]
        except (OSError, IndexError):
            continue  # gone meanwhile, or not ours to read
        if state != b"Z" and (names_it.search(cmdline) or names_it.search(environ)):
            shown = cmdline.replace(b"\x00", b" ").decode(errors="replace").strip()
            found.append(f"{entry.name}: {shown}")
    return found


def _kill_group(proc: psutil.Process) -> None:
    """SIGKILL a hung agent, and its process group (its components) when it leads one."""
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    with contextlib.suppress(psutil.Error, ProcessLookupError, PermissionError):
        if os.getpgid(proc.pid) == proc.pid:
            os.killpg(proc.pid, signal.SIGKILL)
        else:
            proc.kill()


def stop_processes(lab: Lab, lab_dir: Path | None = None, *, grace: float = 5.0) -> list[str]:
    """SIGTERM every live agent of the lab (lab.json's, and with `lab_dir` every process the scan
    finds), wait up to `grace` s, SIGKILL leftovers with their process groups.

    Returns one line per robot, and per process found that lab.json did not name, saying what
    happened (for the user).
    """
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    report: list[str] = []
    procs: dict[int, tuple[str, psutil.Process]] = {}
    for robot in lab.robots:
        if robot.pid is None:
            report.append(f"{robot.name}: never started")
        elif not is_agent_process(robot.pid, robot):
            report.append(f"{robot.name}: pid {robot.pid} is not running (stale)")
        else:
            with contextlib.suppress(psutil.Error):
                procs[robot.pid] = (robot.name, psutil.Process(robot.pid))
    if lab_dir is not None:
        for proc in lab_processes(lab_dir):
            if proc.pid not in procs:
                procs[proc.pid] = (f"{_describe(proc, lab)} (not in lab.json)", proc)
    for _, proc in procs.values():
        with contextlib.suppress(psutil.Error):
            proc.send_signal(signal.SIGTERM)
    _, alive = psutil.wait_procs([p for _, p in procs.values()], timeout=grace)
    for proc in alive:
        _kill_group(proc)
    psutil.wait_procs(alive, timeout=2.0)
    killed = {p.pid for p in alive}
    for pid, (name, _) in procs.items():
        how = f"killed (no exit {grace:g} s after SIGTERM)" if pid in killed else "stopped"
        report.append(f"{name}: pid {pid} {how}")
    return sorted(report)


def _describe(proc: psutil.Process, lab: Lab) -> str:
    """Who a process found by the scan is: the robot whose data dir its agent runs in, else
    its program."""
    import psutil  # noqa: PLC0415 - client commands read lab.json without it

    try:
        cmdline = proc.cmdline()
    except psutil.Error:
        return "a process (gone)"
    dirs = _data_dirs(cmdline)
    for robot in lab.robots:
        if is_agent_command(cmdline) and os.path.realpath(robot.data_dir) in dirs:
            return robot.name
    return f"a process ({Path(cmdline[0]).name if cmdline else '?'})"


def lab_down(lab_dir: Path, *, grace: float = 5.0, lock_wait: float = LOCK_WAIT) -> list[str]:
    """Stop every agent of the lab in `lab_dir` (lab.json's and every process carrying the lab's
    mark, once no `lab up` is starting more) and remove lab.json."""
    if not lab_dir.is_dir():
        raise SdrpeerError(f"no lab in {lab_dir} (no such directory); nothing to stop")
    with lab_lock(lab_dir, lock_wait) as held:
        report = [] if held else [f"a lab up still starting after {lock_wait:g} s: not waited for"]
        lab = read_lab(lab_dir)
        if lab is None and not lab_processes(lab_dir):
            raise SdrpeerError(f"no lab in {lab_dir} (no {LAB_FILE}); nothing to stop")
        report += stop_processes(lab or Lab(robots=[], key_file=""), lab_dir, grace=grace)
        lab_path(lab_dir).unlink(missing_ok=True)
    return report


def lab_status(lab_dir: Path) -> list[dict[str, Any]]:
    """One dict per robot: the lab.json entry (without token) plus `running`."""
    lab = read_lab(lab_dir)
    if lab is None:
        raise SdrpeerError(f"no lab in {lab_dir} (no {LAB_FILE}); start one with sdrpeer lab up")
    status = []
    for robot in lab.robots:
        entry = {k: v for k, v in asdict(robot).items() if k != "token"}
        entry["running"] = robot.pid is not None and is_agent_process(robot.pid, robot)
        status.append(entry)
    return status
