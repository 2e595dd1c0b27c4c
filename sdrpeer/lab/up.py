"""`sdrpeer lab up`: start N agents on loopback, wait until they see each other, watch them.

How it works: every agent binds port 0 (gossip and API) and writes `DATA_DIR/agent.json`
(`name`, `gossip`, `api`, `pid`) once bound. The lab starts robot-1, waits for its agent.json,
then starts the others with `--join <robot-1 gossip>`, and polls every agent's `/v1/members`
until each sees all N alive. Everything is bounded by one deadline; a timeout or an agent that
exits is reported with the robot's name and log path (plus the log's last lines). lab.json is
rewritten after every step so `sdrpeer lab down` works even if this command dies.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any

import sdrpeer
from sdrpeer.client import AgentClient
from sdrpeer.config import LAB_PRESET
from sdrpeer.errors import ApiError, SdrpeerError
from sdrpeer.lab.files import (
    Lab,
    LabRobot,
    default_robot_files,
    lab_path,
    new_cluster_key,
    new_token,
    read_lab,
    robot_name,
    write_lab,
    write_robot_file,
    write_secret,
)
from sdrpeer.lab.procs import (
    lab_env,
    lab_lock,
    lab_processes,
    running_pids,
    start_time,
    stop_processes,
)
from sdrpeer.netlab import net
from sdrpeer.netlab.plan import NetPlan
from sdrpeer.vocabulary import MemberState

POLL = 0.1
LOG_TAIL_LINES = 12


@dataclass(frozen=True, slots=True)
class UpOptions:
    """What `sdrpeer lab up` was asked for."""

    robots: int
    lab_dir: Path
    preset: str = LAB_PRESET
    """Every agent's timers (`sdrpeer.agent.tuning`): `lab` holds on a busy machine; tests
    that want quick verdicts pass `fast_test`."""
    robot_files: Path | None = None
    """Where robot-K.yaml files are taken from (None = examples/robots, when there is one)."""
    scenario: Path | None = None
    timeout: float = 20.0
    netns: bool = False
    """Each robot in its own network namespace on a private bridge (root; sdrpeer.netlab)."""
    discover: bool = False
    """Robots find each other by mDNS (`--discover`) instead of joining robot-1 (a namespace
    lab: multicast needs a network segment, loopback has none)."""
    allow_launchers: tuple[str, ...] = ()
    """Launchers every agent lets its hosts use besides `python` (`sdrpeer agent
    --allow-launcher`): none unless named, as on any agent."""


@dataclass(slots=True)
class RunningLab:
    """A started lab: lab.json contents plus the agent processes this command owns."""

    lab_dir: Path
    lab: Lab
    procs: dict[str, subprocess.Popen[bytes]] = field(default_factory=dict)
    net: NetPlan | None = None
    """The namespace lab's network, if it has one."""
    options: UpOptions | None = None
    """What the lab was started with (restarting an agent needs it)."""

    def restart(self, name: str) -> None:
        """Start robot `name`'s agent again (same data dir, key and token), joining an alive
        robot; its new pid is recorded in lab.json. Nothing happens while its agent runs."""
        assert self.options is not None
        robot = self.lab.robot(name)
        assert robot is not None
        if self._alive(name):
            return  # it runs: a second agent for one robot would be left behind at stop
        seeds = [r.gossip for r in self.lab.robots if r.name != name and self._alive(r.name)]
        command = agent_command(
            robot,
            self.options,
            Path(self.lab.key_file),
            seeds[0] if seeds else None,
            self.net,
            scenario_start=self.lab.created,
        )
        (Path(robot.data_dir) / "agent.json").unlink(missing_ok=True)  # the new life writes its own
        with lab_lock(self.lab_dir):
            if not lab_path(self.lab_dir).exists():
                raise SdrpeerError(f"{name}: not restarted: the lab was taken down (lab down)")
            self.spawn(robot, command)

    def spawn(self, robot: LabRobot, command: list[str]) -> None:
        """Start `robot`'s agent and record it in lab.json at once (pid and start time)."""
        self.procs[robot.name] = _spawn(command, Path(robot.log), self.lab_dir)
        robot.pid = self.procs[robot.name].pid
        robot.started = start_time(robot.pid)
        write_lab(self.lab_dir, self.lab)

    def wait_started(self, name: str, timeout: float) -> None:
        """Wait until robot `name`'s agent has written its addresses (after `restart`: a lab on
        loopback binds new ports) and record them in lab.json; SdrpeerError after `timeout`."""
        robot = self.lab.robot(name)
        assert robot is not None
        _wait_addresses(self, robot, time.monotonic() + timeout)
        write_lab(self.lab_dir, self.lab)

    def process(self, name: str) -> subprocess.Popen[bytes] | None:
        """The agent process of robot `name` this command started (None: none)."""
        return self.procs.get(name)

    def _alive(self, name: str) -> bool:
        proc = self.procs.get(name)
        return proc is not None and proc.poll() is None

    def problems(self) -> list[str]:
        """One line per agent process that has exited."""
        return [
            f"{name}: agent exited with code {proc.returncode}; see {self._log(name)}"
            for name, proc in self.procs.items()
            if proc.poll() is not None
        ]

    def stop(self, *, grace: float = 5.0) -> list[str]:
        """Stop every agent of the lab (SIGTERM, then SIGKILL), those lab.json names and every
        other process carrying the lab's mark, reap the ones this command started and remove
        lab.json."""
        report = stop_processes(self.lab, self.lab_dir, grace=grace)
        for proc in self.procs.values():
            try:
                proc.wait(timeout=grace)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait()
        lab_path(self.lab_dir).unlink(missing_ok=True)
        if self.net is not None:
            report += [f"not removed: {name}" for name in net.destroy(self.lab_dir)]
        return report

    def _log(self, name: str) -> str:
        robot = self.lab.robot(name)
        return robot.log if robot else "?"


def log_tail(path: Path | str, lines: int = LOG_TAIL_LINES) -> str:
    """The last `lines` lines of a log file, indented (empty when unreadable)."""
    try:
        text = Path(path).read_text(errors="replace")
    except OSError:
        return ""
    tail = text.rstrip("\n").splitlines()[-lines:]
    return "\n".join(f"    | {line}" for line in tail)


def _fail(robot: LabRobot, message: str) -> SdrpeerError:
    tail = log_tail(robot.log)
    suffix = f"; last lines of {robot.log}:\n{tail}" if tail else f"; see {robot.log}"
    return SdrpeerError(f"{robot.name}: {message}{suffix}")


def agent_command(
    robot: LabRobot,
    options: UpOptions,
    key_file: Path,
    join: str | None,
    network: NetPlan | None = None,
    *,
    scenario_start: float | None = None,
) -> list[str]:
    """The command line that starts one lab agent (inside its namespace in a namespace lab, its
    gossip, API and component hosts on its bridge address; else on loopback, any free port).
    `scenario_start`: the lab's clock for the scenario (lab.json's `created`)."""
    data_dir = Path(robot.data_dir)
    host = "127.0.0.1" if network is None else network.address(robot.name)
    ports = ("0", "0") if network is None else ("7946", "8080")
    prefix = [] if network is None else network.in_ns(robot.name)
    command = [
        *prefix,
        sys.executable,
        "-m",
        "sdrpeer",
        "agent",
        "--name",
        robot.name,
        "--bind",
        f"{host}:{ports[0]}",
        "--api",
        f"{host}:{ports[1]}",
        "--data-dir",
        str(data_dir),
        "--key-file",
        str(key_file),
        "--token-file",
        str(data_dir / "token"),
        "--robot-file",
        str(data_dir / "robot.yaml"),
        "--preset",
        options.preset,
    ]
    if options.scenario is not None:
        command += ["--scenario", str(options.scenario.resolve())]
        if scenario_start is not None:
            command += ["--scenario-start", repr(scenario_start)]
    for launcher in options.allow_launchers:
        command += ["--allow-launcher", launcher]
    if options.discover:
        command.append("--discover")
    elif join is not None:
        command += ["--join", join]
    return command


def _spawn(command: list[str], log: Path, lab_dir: Path) -> subprocess.Popen[bytes]:
    """Start an agent in its own session, marked as the lab's (`sdrpeer.lab.procs`)."""
    env = lab_env(lab_dir, os.environ)
    package_root = str(Path(sdrpeer.__file__).resolve().parents[1])
    env["PYTHONPATH"] = os.pathsep.join(p for p in (package_root, env.get("PYTHONPATH")) if p)
    with log.open("ab") as out:
        return subprocess.Popen(
            command,
            stdin=subprocess.DEVNULL,
            stdout=out,
            stderr=subprocess.STDOUT,
            start_new_session=True,
            env=env,
        )


def read_agent_json(data_dir: Path | str) -> dict[str, Any] | None:
    """DATA_DIR/agent.json once it is complete (gossip and api present), else None."""
    try:
        data = json.loads((Path(data_dir) / "agent.json").read_text())
    except (OSError, json.JSONDecodeError):
        return None
    if isinstance(data, dict) and data.get("gossip") and data.get("api"):
        return data
    return None


def _wait_addresses(running: RunningLab, robot: LabRobot, deadline: float) -> None:
    proc = running.procs[robot.name]
    while True:
        info = read_agent_json(robot.data_dir)
        if info is not None:
            robot.gossip, robot.api = str(info["gossip"]), str(info["api"]).rstrip("/")
            return
        if proc.poll() is not None:
            raise _fail(robot, f"agent exited with code {proc.returncode} while starting")
        if time.monotonic() > deadline:
            agent_json = Path(robot.data_dir) / "agent.json"
            raise _fail(robot, f"no {agent_json} within the start timeout")
        time.sleep(POLL)


def _missing_alive(robot: LabRobot, names: set[str]) -> str | None:
    """What robot is still missing (None when it sees all `names` alive)."""
    try:
        members = AgentClient(str(robot.api), timeout=1.0).members()
    except ApiError as exc:
        return str(exc)
    alive = {m.get("name") for m in members if m.get("state") == MemberState.ALIVE}
    missing = sorted(names - alive)
    if not missing:
        return None
    seen = len(names) - len(missing)
    return f"sees {seen} of {len(names)} alive (missing {', '.join(missing)})"


def _wait_converged(running: RunningLab, deadline: float) -> None:
    names = {r.name for r in running.lab.robots}
    pending = list(running.lab.robots)
    while pending:
        for robot in pending:
            proc = running.procs[robot.name]
            if proc.poll() is not None:
                raise _fail(robot, f"agent exited with code {proc.returncode}")
        lacking = {r.name: _missing_alive(r, names) for r in pending}
        pending = [r for r in pending if lacking[r.name] is not None]
        if pending and time.monotonic() > deadline:
            robot = pending[0]
            raise _fail(robot, f"the lab did not converge in time: {lacking[robot.name]}")
        if pending:
            time.sleep(POLL * 2)


def _prepare(options: UpOptions) -> Lab:
    lab_dir = options.lab_dir
    lab_dir.mkdir(parents=True, exist_ok=True)
    existing = read_lab(lab_dir)
    running = list(running_pids(existing)) if existing is not None else []
    if not running and lab_processes(lab_dir):
        running = ["agents lab.json does not name"]
    if running:
        raise SdrpeerError(
            f"a lab is already running in {lab_dir} ({', '.join(running)}); "
            f"stop it with: sdrpeer lab down --dir {lab_dir}"
        )
    robot_files = options.robot_files or default_robot_files()
    if options.robot_files is not None and not options.robot_files.is_dir():
        raise SdrpeerError(f"--robot-files {options.robot_files}: no such directory")
    key_file = new_cluster_key(lab_dir).resolve()
    robots = []
    for index in range(1, options.robots + 1):
        name = robot_name(index)
        data_dir = (lab_dir / name).resolve()
        write_robot_file(data_dir, index, robot_files)
        (data_dir / "agent.json").unlink(missing_ok=True)
        token = new_token()
        write_secret(data_dir / "token", token + "\n")
        robots.append(LabRobot(name, str(data_dir), str(data_dir / "agent.log"), token))
    return Lab(robots=robots, key_file=str(key_file))


def _check_scenario(path: Path | None, lab: Lab) -> None:
    """Refuse a scenario that this lab's robots cannot play before any agent starts: a step for
    a robot the lab does not have (ScenarioError naming file, line and robot), a ramp or move
    with nothing to start from. Each agent alone knows only its own robot, and would skip the
    others' steps without a word."""
    if path is None:
        return
    from sdrpeer.monitor.scenario import Scenario  # noqa: PLC0415 - YAML: only with a scenario
    from sdrpeer.monitor.virtual import RobotFile  # noqa: PLC0415

    files = [
        replace(RobotFile.load(Path(r.data_dir) / "robot.yaml"), name=r.name) for r in lab.robots
    ]
    Scenario.load(path, robots=files)


def _check_launchers(names: tuple[str, ...]) -> None:
    """Refuse an unknown launcher name before any agent starts (each agent would refuse it)."""
    if not names:
        return
    from sdrpeer.launch.launchers import known_launchers  # noqa: PLC0415 - plugins: entry points

    known = known_launchers()
    unknown = [n for n in names if n not in known]
    if unknown:
        raise SdrpeerError(
            f"--allow-launcher {unknown[0]!r}: unknown launcher (known: {', '.join(known)})"
        )


def start_lab(options: UpOptions, say: Callable[[str], None] = print) -> RunningLab:
    """Start the lab's agents and wait until all of them see every robot alive."""
    if options.robots < 1:
        raise SdrpeerError(f"--robots must be at least 1, got {options.robots}")
    if options.discover and not options.netns:
        raise SdrpeerError("--discover needs --netns: loopback carries no multicast")
    _check_launchers(options.allow_launchers)
    lab = _prepare(options)
    _check_scenario(options.scenario, lab)
    running = RunningLab(options.lab_dir, lab, options=options)
    deadline = time.monotonic() + options.timeout
    try:
        _start_agents(running, options, deadline, say)
        _wait_converged(running, deadline)
    except BaseException:
        running.stop(grace=2.0)
        raise
    return running


def _start_agents(
    running: RunningLab, options: UpOptions, deadline: float, say: Callable[[str], None]
) -> None:
    """Spawn every agent (robot-1 first, the others joining it), each recorded in lab.json as it
    is spawned, and wait for their addresses. The lab's lock is held until the last one is
    spawned: a `lab down` meanwhile waits, then finds them all."""
    lab = running.lab
    key_file = Path(lab.key_file)
    first, *others = lab.robots
    with lab_lock(options.lab_dir):
        if options.netns:
            running.net = net.create(options.lab_dir, options.robots)
            say(f"network: bridge {running.net.bridge}, robots on 10.213.{running.net.lab_id}.0/24")
        say(f"starting {len(lab.robots)} agents in {options.lab_dir} (preset {options.preset})")
        command = agent_command(
            first, options, key_file, None, running.net, scenario_start=lab.created
        )
        running.spawn(first, command)
        _wait_addresses(running, first, deadline)
        write_lab(options.lab_dir, lab)
        for robot in others:
            command = agent_command(
                robot, options, key_file, first.gossip, running.net, scenario_start=lab.created
            )
            running.spawn(robot, command)
    for robot in others:
        _wait_addresses(running, robot, deadline)
    write_lab(options.lab_dir, lab)


@contextmanager
def started_lab(options: UpOptions, say: Callable[[str], None] = print) -> Iterator[RunningLab]:
    """Start a lab, and stop it (cleanly) when the block ends, however it ends."""
    running = start_lab(options, say)
    try:
        yield running
    finally:
        for line in running.stop():
            say(f"  {line}")
