"""Lab files and teardown without real agents: lab.json, secrets, robot files, `lab down`."""

from __future__ import annotations

import io
import json
import os
import stat
import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from sdrpeer.cli.lab import watch
from sdrpeer.errors import SdrpeerError
from sdrpeer.gossip.wire import Keyring
from sdrpeer.lab.files import (
    Lab,
    LabRobot,
    lab_path,
    new_cluster_key,
    read_lab,
    robot_file_text,
    write_lab,
    write_robot_file,
)
from sdrpeer.lab.procs import (
    LOCK_FILE,
    is_agent_process,
    lab_down,
    lab_lock,
    lab_status,
    running_pids,
    start_time,
)
from sdrpeer.lab.procs import processes_naming as lab_survivors
from sdrpeer.lab.up import RunningLab, UpOptions, agent_command, log_tail, read_agent_json
from sdrpeer.monitor.virtual import RobotFile
from tests.realnet import kill_all
from tests.wait import until

# A stand-in whose command line looks like `python -m sdrpeer agent --data-dir D`.
FAKE_AGENT = "import signal, sys, time\n{setup}\nprint('ready', flush=True)\ntime.sleep(60)\n"


def robot(tmp_path: Path, name: str, pid: int | None = None) -> LabRobot:
    data_dir = tmp_path / name
    return LabRobot(name, str(data_dir), str(data_dir / "agent.log"), f"tok-{name}", pid=pid)


@pytest.fixture
def spawn(tmp_path: Path) -> Iterator[list[subprocess.Popen[str]]]:
    procs: list[subprocess.Popen[str]] = []
    yield procs
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait()
        if proc.stdout:
            proc.stdout.close()


def start_fake(
    procs: list[subprocess.Popen[str]], data_dir: str, *, ignore_term: bool = False
) -> subprocess.Popen[str]:
    setup = "signal.signal(signal.SIGTERM, signal.SIG_IGN)" if ignore_term else ""
    command = [sys.executable, "-c", FAKE_AGENT.format(setup=setup)]
    command += ["-m", "sdrpeer", "agent", "--data-dir", data_dir]
    proc = subprocess.Popen(command, stdout=subprocess.PIPE, text=True, start_new_session=True)
    procs.append(proc)
    assert proc.stdout is not None
    assert proc.stdout.readline() == "ready\n"
    return proc


def test_lab_json_round_trip_and_mode(tmp_path: Path) -> None:
    lab = Lab(robots=[robot(tmp_path, "robot-1", pid=42)], key_file="/k", created=1.5)
    lab.robots[0].api = "http://127.0.0.1:1234"
    write_lab(tmp_path, lab)
    assert stat.S_IMODE(os.stat(lab_path(tmp_path)).st_mode) == 0o600
    data = json.loads(lab_path(tmp_path).read_text())
    assert data == {
        "robots": [
            {
                "name": "robot-1",
                "data_dir": str(tmp_path / "robot-1"),
                "log": str(tmp_path / "robot-1" / "agent.log"),
                "token": "tok-robot-1",
                "pid": 42,
                "started": None,
                "api": "http://127.0.0.1:1234",
                "gossip": None,
            }
        ],
        "key_file": "/k",
        "created": 1.5,
    }
    assert read_lab(tmp_path) == lab
    assert read_lab(tmp_path / "nowhere") is None


def test_broken_lab_json_says_where(tmp_path: Path) -> None:
    lab_path(tmp_path).write_text("{not json")
    with pytest.raises(SdrpeerError, match=r"lab\.json: not a lab file"):
        read_lab(tmp_path)


def test_cluster_key_is_32_bytes_hex_private(tmp_path: Path) -> None:
    path = new_cluster_key(tmp_path)
    assert stat.S_IMODE(os.stat(path).st_mode) == 0o600
    assert len(bytes.fromhex(path.read_text().strip())) == 32
    assert len(Keyring.from_file(path).signing_key) == 32


def test_generated_robot_files_are_valid(tmp_path: Path) -> None:
    facts = RobotFile.parse(robot_file_text(3), "robot-3.yaml")
    assert facts.name == "robot-3"
    assert facts.memory == 4_000_000_000
    assert facts.battery == 100.0
    assert facts.position == (6.0, 0.0)
    assert facts.rssi == -45.0
    path = write_robot_file(tmp_path / "robot-3", 3, None)
    assert RobotFile.load(path) == facts


def test_robot_files_are_copied_when_present(tmp_path: Path) -> None:
    source = tmp_path / "examples"
    source.mkdir()
    (source / "robot-1.yaml").write_text("name: robot-1\nmemory: 2GB\n")
    copied = write_robot_file(tmp_path / "r1", 1, source)
    assert copied.read_text() == "name: robot-1\nmemory: 2GB\n"
    assert "memory: 4GB" in write_robot_file(tmp_path / "r2", 2, source).read_text()


def test_agent_command_flags(tmp_path: Path) -> None:
    entry = robot(tmp_path, "robot-2")
    options = UpOptions(robots=2, lab_dir=tmp_path, preset="lan")
    command = agent_command(entry, options, tmp_path / "cluster.key", "127.0.0.1:5000")
    assert command[:4] == [sys.executable, "-m", "sdrpeer", "agent"]
    args = dict(zip(command[4::2], command[5::2], strict=True))
    assert args == {
        "--name": "robot-2",
        "--bind": "127.0.0.1:0",
        "--api": "127.0.0.1:0",
        "--data-dir": entry.data_dir,
        "--key-file": str(tmp_path / "cluster.key"),
        "--token-file": str(Path(entry.data_dir) / "token"),
        "--robot-file": str(Path(entry.data_dir) / "robot.yaml"),
        "--preset": "lan",
        "--join": "127.0.0.1:5000",
    }


def test_read_agent_json_waits_for_a_complete_file(tmp_path: Path) -> None:
    assert read_agent_json(tmp_path) is None
    (tmp_path / "agent.json").write_text('{"name": "robot-1", "gossip": "127.0.0.1:1"')
    assert read_agent_json(tmp_path) is None
    info = {"name": "robot-1", "gossip": "127.0.0.1:1", "api": "http://127.0.0.1:2", "pid": 9}
    (tmp_path / "agent.json").write_text(json.dumps(info))
    assert read_agent_json(tmp_path) == info


def test_log_tail(tmp_path: Path) -> None:
    log = tmp_path / "agent.log"
    log.write_text("".join(f"line {i}\n" for i in range(20)))
    assert log_tail(log, 2) == "    | line 18\n    | line 19"
    assert log_tail(tmp_path / "missing.log") == ""


def test_down_with_stale_pids_signals_nothing(
    tmp_path: Path, spawn: list[subprocess.Popen[str]]
) -> None:
    # A live process that is not this robot's agent (another lab's data dir) must not be touched.
    other = start_fake(spawn, str(tmp_path / "elsewhere" / "robot-2"))
    gone = subprocess.Popen([sys.executable, "-c", "pass"])
    gone.wait()
    lab_dir = tmp_path / "lab"
    robots = [
        robot(lab_dir, "robot-1", pid=gone.pid),
        robot(lab_dir, "robot-2", pid=other.pid),
        robot(lab_dir, "robot-3", pid=None),
    ]
    write_lab(lab_dir, Lab(robots=robots, key_file="k"))
    assert running_pids(Lab(robots=robots, key_file="k")) == {}
    report = lab_down(lab_dir, grace=0.5)
    assert report == [
        f"robot-1: pid {gone.pid} is not running (stale)",
        f"robot-2: pid {other.pid} is not running (stale)",
        "robot-3: never started",
    ]
    assert other.poll() is None
    assert not lab_path(lab_dir).exists()


def test_down_stops_agents_and_kills_the_stubborn(
    tmp_path: Path, spawn: list[subprocess.Popen[str]]
) -> None:
    polite = robot(tmp_path, "robot-1")
    stubborn = robot(tmp_path, "robot-2")
    polite.pid = start_fake(spawn, polite.data_dir).pid
    stubborn.pid = start_fake(spawn, stubborn.data_dir, ignore_term=True).pid
    write_lab(tmp_path, Lab(robots=[polite, stubborn], key_file="k"))
    assert is_agent_process(polite.pid, polite)
    assert not is_agent_process(polite.pid, stubborn)
    status = lab_status(tmp_path)
    assert [(s["name"], s["running"]) for s in status] == [("robot-1", True), ("robot-2", True)]
    assert "token" not in status[0]
    report = lab_down(tmp_path, grace=0.5)
    assert report == [
        f"robot-1: pid {polite.pid} stopped",
        f"robot-2: pid {stubborn.pid} killed (no exit 0.5 s after SIGTERM)",
    ]
    # Both are gone (psutil reaped them, so Popen cannot see the signal numbers).
    assert [p.wait(timeout=5) is not None for p in spawn] == [True, True]
    assert not is_agent_process(polite.pid, polite)
    assert not is_agent_process(stubborn.pid, stubborn)


def test_down_and_status_without_a_lab(tmp_path: Path) -> None:
    with pytest.raises(SdrpeerError, match="nothing to stop"):
        lab_down(tmp_path)
    with pytest.raises(SdrpeerError, match="start one with sdrpeer lab up"):
        lab_status(tmp_path)


def test_watch_appends_frames_when_piped(tmp_path: Path) -> None:
    now = [0.0]

    def sleep(seconds: float) -> None:
        now[0] += seconds

    running = RunningLab(tmp_path, Lab(robots=[robot(tmp_path, "robot-1", pid=1)], key_file="k"))
    out = io.StringIO()
    watch(running, 2.0, out, clock=lambda: now[0], sleep=sleep)
    frames = out.getvalue().split("\n\n")
    assert len(frames) == 3
    assert frames[0] == f"lab {tmp_path}: 1 robots, 0 of 2 s  (Ctrl-C to stop)\nno agent is running"
    assert frames[2].startswith(f"lab {tmp_path}: 1 robots, 2 of 2 s")
    assert "\x1b[" not in out.getvalue()


def test_down_stops_what_the_lab_spawned_but_never_recorded(tmp_path: Path) -> None:
    """`lab up` died between spawning an agent and writing its pid into lab.json (as a crash or
    SIGKILL at that moment leaves it): `lab down` still stops it, and a process that carries
    the lab's mark without looking like an agent (a host whose agent died) too."""
    lab_dir = tmp_path / "lab"
    entry = robot(lab_dir.resolve(), "robot-2")
    Path(entry.data_dir).mkdir(parents=True)
    running = RunningLab(lab_dir, Lab(robots=[entry], key_file="k"))
    agent = [sys.executable, "-c", FAKE_AGENT.format(setup=""), "-m", "sdrpeer", "agent"]
    running.spawn(entry, [*agent, "--data-dir", entry.data_dir])
    marked_only = LabRobot("host", entry.data_dir, entry.log, "t")
    running.spawn(marked_only, [sys.executable, "-c", "import time; time.sleep(60)"])
    procs = list(running.procs.values())
    try:
        entry.pid = entry.started = None  # what lab.json held when `lab up` died
        write_lab(lab_dir, Lab(robots=[entry], key_file="k"))
        until(
            "both processes started",
            lambda: lab_survivors(lab_dir),
            lambda found: len(found) == 2,
            within=10,
            poll=0.05,
        )
        report = lab_down(lab_dir, grace=2)
        program = Path(sys.executable).name
        assert report == sorted(
            [
                "robot-2: never started",
                f"robot-2 (not in lab.json): pid {procs[0].pid} stopped",
                f"a process ({program}) (not in lab.json): pid {procs[1].pid} stopped",
            ]
        )
        assert lab_survivors(lab_dir) == []
    finally:
        kill_all(procs)


def test_a_recorded_start_time_tells_a_reused_pid_apart(
    tmp_path: Path, spawn: list[subprocess.Popen[str]]
) -> None:
    entry = robot(tmp_path, "robot-1")
    entry.pid = start_fake(spawn, entry.data_dir).pid
    entry.started = start_time(entry.pid)
    assert entry.started is not None
    assert is_agent_process(entry.pid, entry)
    entry.started -= 60.0  # lab.json's agent started a minute before this process did
    assert not is_agent_process(entry.pid, entry)
    assert running_pids(Lab(robots=[entry], key_file="k")) == {}


def lock_holders(path: Path) -> int:
    """How many of this process's file descriptors are open on `path`."""
    fds = Path("/proc/self/fd").iterdir()
    return sum(1 for fd in fds if os.path.realpath(fd) == os.path.realpath(path))


def test_down_waits_for_a_lab_up_still_spawning_then_stops_what_it_spawned(
    tmp_path: Path,
) -> None:
    """`lab down` asked while `lab up` holds the lab's lock (it is spawning agents) waits for it,
    so an agent spawned after down was asked is stopped too, not left behind."""
    lab_dir = tmp_path / "lab"
    entry = robot(lab_dir.resolve(), "robot-1")
    Path(entry.data_dir).mkdir(parents=True)
    running = RunningLab(lab_dir, Lab(robots=[entry], key_file="k"))
    write_lab(lab_dir, running.lab)
    agent = [sys.executable, "-c", FAKE_AGENT.format(setup=""), "-m", "sdrpeer", "agent"]
    with ThreadPoolExecutor(1) as pool:
        try:
            with lab_lock(lab_dir):  # as lab up holds it while it spawns
                down = pool.submit(lab_down, lab_dir, grace=2)
                until(  # its own descriptor of lab.lock open beside ours: it is waiting
                    "lab down waiting for the lock",
                    lambda: lock_holders(lab_dir / LOCK_FILE),
                    lambda n: n == 2 and not down.done(),
                    within=5,
                    poll=0.02,
                )
                running.spawn(entry, [*agent, "--data-dir", entry.data_dir])
            report = down.result(timeout=60)
            assert report == [f"robot-1: pid {entry.pid} stopped"]
            assert lab_survivors(lab_dir) == []
        finally:
            kill_all(running.procs.values())
