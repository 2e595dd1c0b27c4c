"""Helpers for the real-network tests: start real agent processes on loopback and poll their API.

How it works: a `RealCluster` owns a temporary directory with one cluster key (generated with
`Keyring.generate()`) and starts agents as `python -m sdrpeer agent --preset fast_test --bind
127.0.0.1:0 --api 127.0.0.1:0`, each in its own session with its output in `<data dir>/agent.log`.
`start` waits for `agent.json` (the bound addresses); `wait_until` polls a condition every 0.1 s
for at most 15 s by default and fails with a message that names what was awaited, the last value
seen and the tail of every agent's log. `close` SIGKILLs whatever is still running, so a failed or
interrupted test leaves no process behind: every agent carries the cluster directory as its lab
mark (`sdrpeer.lab.procs`), so one the list missed is found too.
"""

from __future__ import annotations

import contextlib
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import urllib.error
import urllib.request
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, TypeVar

import psutil
import pytest

from sdrpeer.gossip.wire import Keyring, format_key
from sdrpeer.lab.procs import lab_env, lab_processes
from tests import wait

REPO = Path(__file__).resolve().parents[1]
POLL = 0.1
WAIT = 15.0
START_WAIT = 15.0
NETNS_ONLY = pytest.mark.skipif(
    os.geteuid() != 0 or not all(shutil.which(t) for t in ("ip", "iptables", "tc")),
    reason="NAMESPACE LAB NOT TESTED: needs root with ip, iptables and tc "
    "(tools/check installs iptables as root)",
)
"""Marks a test of the namespace lab (sdrpeer.netlab): it needs root and the tools."""
LOG_TAIL = 15
T = TypeVar("T")


class RealnetError(AssertionError):
    """A bounded wait ran out, or an agent misbehaved; the message says what and shows logs."""


def http(
    method: str, url: str, body: Any = None, token: str | None = None, timeout: float = 2.0
) -> tuple[int, Any]:
    """(status, decoded JSON body) of one HTTP call; HTTP errors are returned, not raised."""
    data = None if body is None else json.dumps(body).encode()
    headers = {"Accept": "application/json"}
    if data is not None:
        headers["Content-Type"] = "application/json"
    if token is not None:
        headers["Authorization"] = f"Bearer {token}"
    req = urllib.request.Request(url, data=data, headers=headers, method=method)
    try:
        with urllib.request.urlopen(req, timeout=timeout) as resp:
            status, raw = resp.status, resp.read()
    except urllib.error.HTTPError as exc:
        status, raw = exc.code, exc.read()
    return status, json.loads(raw) if raw else None


def log_tail(path: Path, lines: int = LOG_TAIL) -> str:
    """The last lines of a log, indented (or a note when there is none)."""
    try:
        text = path.read_text(errors="replace")
    except OSError:
        return "    (no log)"
    tail = text.rstrip("\n").splitlines()[-lines:]
    return "\n".join(f"    | {line}" for line in tail) or "    (empty log)"


@dataclass
class Agent:
    """One agent process started by a `RealCluster`."""

    name: str
    data_dir: Path
    proc: subprocess.Popen[bytes]
    gossip: str = ""
    api: str = ""
    pid: int = 0
    stopped: bool = False
    """Set when the test stops the agent on purpose (its exit is then not a failure)."""

    @property
    def log(self) -> Path:
        """Where the agent's stdout and stderr go."""
        return self.data_dir / "agent.log"

    @property
    def gossip_addr(self) -> tuple[str, int]:
        """The bound UDP gossip address."""
        host, _, port = self.gossip.rpartition(":")
        return host, int(port)

    @property
    def token(self) -> str:
        """The API token the agent generated into DATA_DIR/token."""
        return (self.data_dir / "token").read_text().strip()

    def running(self) -> bool:
        """Whether the process has not exited."""
        return self.proc.poll() is None

    def get(self, path: str) -> Any:
        """GET an API path; an error status raises RealnetError."""
        status, body = http("GET", self.api + path)
        if status != 200:
            raise RealnetError(f"{self.name}: GET {path} answered {status}: {body}")
        return body

    def members(self) -> dict[str, dict[str, Any]]:
        """GET /v1/members as name -> member."""
        return {m["name"]: m for m in self.get("/v1/members")}

    def member(self, name: str) -> dict[str, Any]:
        """One member as this agent sees it (KeyError while it does not know it)."""
        return self.members()[name]

    def states(self) -> dict[str, str]:
        """name -> state as this agent sees it."""
        return {name: m["state"] for name, m in self.members().items()}

    def agent_info(self) -> dict[str, Any]:
        """GET /v1/agent."""
        return dict(self.get("/v1/agent"))

    def events(self) -> list[dict[str, Any]]:
        """GET /v1/events (everything still in the log)."""
        return list(self.get("/v1/events?limit=10000"))


@dataclass
class RealCluster:
    """Real agents on 127.0.0.1 sharing one cluster key; `close()` kills them all."""

    root: Path
    preset: str = "fast_test"
    agents: list[Agent] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.root.mkdir(parents=True, exist_ok=True)
        self.key = Keyring.generate()
        self.key_file = self.root / "cluster.key"
        self.key_file.write_text(format_key(self.key) + "\n")
        os.chmod(self.key_file, 0o600)

    # ------------------------------------------------------------------ processes
    def robot_file(self, name: str) -> Path:
        """A deterministic robot file: no noise, no drain, battery 100 %, -45 dBm."""
        path = self.root / f"{name}.yaml"
        if not path.exists():
            index = len(list(self.root.glob("*.yaml")))
            path.write_text(
                f"name: {name}\nmemory: 4GB\ncpus: 4\nbattery: 100%\n"
                f"position: [{3 * index}, 0]\nrssi: -45dBm\n"
            )
        return path

    def start(
        self,
        name: str,
        join: Iterable[Agent] = (),
        *,
        run: int = 0,
        insecure: bool = False,
        flags: Sequence[str] = (),
    ) -> Agent:
        """Start an agent (data dir `name` or `name.run<N>`), wait for its agent.json;
        `insecure`: without the cluster key (`--insecure`); `flags`: more `sdrpeer agent` flags."""
        return self.started(self.spawn(name, join, run=run, insecure=insecure, flags=flags))

    def spawn(
        self,
        name: str,
        join: Iterable[Agent] = (),
        *,
        run: int = 0,
        insecure: bool = False,
        flags: Sequence[str] = (),
    ) -> Agent:
        """Start an agent's process as `start` does, without waiting for it (see `started`)."""
        data_dir = self.root / (name if run == 0 else f"{name}.run{run}")
        data_dir.mkdir(parents=True)
        command = [
            sys.executable,
            "-m",
            "sdrpeer",
            "agent",
            "--name",
            name,
            "--bind",
            "127.0.0.1:0",
            "--api",
            "127.0.0.1:0",
            "--data-dir",
            str(data_dir),
            *(["--insecure"] if insecure else ["--key-file", str(self.key_file)]),
            "--robot-file",
            str(self.robot_file(name)),
            "--preset",
            self.preset,
        ]
        for peer in join:
            command += ["--join", peer.gossip]
        command += flags
        env = lab_env(self.root, os.environ)  # marked: `close` finds whatever escaped the list
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
        env.pop("SDRPEER_API", None)
        env.pop("SDRPEER_TOKEN", None)
        with (data_dir / "agent.log").open("ab") as out:
            proc = subprocess.Popen(
                command,
                stdin=subprocess.DEVNULL,
                stdout=out,
                stderr=subprocess.STDOUT,
                start_new_session=True,
                env=env,
                cwd=self.root,
            )
        agent = Agent(name, data_dir, proc)
        self.agents.append(agent)
        return agent

    def started(self, agent: Agent) -> Agent:
        """`agent` once its agent.json names its addresses (fails if it exits meanwhile)."""

        def exited() -> str | None:
            code = agent.proc.poll()
            return None if code is None else f"{agent.name} exited with code {code}"

        info = wait.until(
            f"{agent.name}'s agent.json",
            lambda: _read_json(agent.data_dir / "agent.json") or {},
            lambda doc: bool(doc.get("gossip") and doc.get("api")),
            within=START_WAIT,
            poll=0.05,
            abort=exited,
            context=lambda: log_tail(agent.log),
        )
        agent.gossip = str(info["gossip"])
        agent.api = str(info["api"]).rstrip("/")
        agent.pid = int(info["pid"])
        return agent

    def start_many(self, n: int, flags: Sequence[str] = ()) -> list[Agent]:
        """robot-1 .. robot-n, the others joining robot-1, and wait until all see n alive and
        hold every robot's record. The others start side by side (each waits only for robot-1's
        address). `flags`: more `sdrpeer agent` flags for every one."""
        first = self.start("robot-1", flags=flags)
        spawned = [self.spawn(f"robot-{i}", join=[first], flags=flags) for i in range(2, n + 1)]
        others = [self.started(agent) for agent in spawned]
        agents = [first, *others]
        names = {a.name for a in agents}
        for agent in agents:
            self.wait_states(agent, dict.fromkeys(names, "alive"), what="convergence")
        for agent in agents:  # and every robot's record has reached every agent: an allocator
            # deciding before a record arrived would leave that robot out of a placement
            self.wait_until(
                agent.members,
                lambda members: all((members.get(n) or {}).get("metrics") for n in names),
                f"{agent.name} to hold every robot's record",
            )
        return agents

    def kill(self, agent: Agent) -> None:
        """SIGKILL the agent (no goodbye) and reap it."""
        agent.stopped = True
        _signal_group(agent.proc, signal.SIGKILL)
        agent.proc.wait(timeout=5)

    def terminate(self, agent: Agent, timeout: float = 5.0) -> int:
        """SIGTERM (graceful leave) and wait for the exit code."""
        agent.stopped = True
        agent.proc.send_signal(signal.SIGTERM)
        try:
            return agent.proc.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            raise RealnetError(
                f"{agent.name}: still running {timeout:g} s after SIGTERM:\n" + log_tail(agent.log)
            ) from None

    def close(self) -> None:
        """SIGKILL every agent that is still running and reap it, then every other process
        carrying the cluster's mark (one whose Popen never returned, a host it left)."""
        for agent in self.agents:
            if agent.proc.poll() is None:
                _signal_group(agent.proc, signal.SIGKILL)
            with contextlib.suppress(subprocess.TimeoutExpired):
                agent.proc.wait(timeout=5)
        for proc in lab_processes(self.root):
            with contextlib.suppress(ProcessLookupError, PermissionError):
                os.killpg(proc.pid, signal.SIGKILL)  # each leads its own session
            with contextlib.suppress(psutil.Error):
                proc.kill()

    # ------------------------------------------------------------------ waiting
    def logs(self) -> str:
        """Every agent's log tail, for failure messages."""
        parts = []
        for a in self.agents:
            state = "running" if a.running() else f"exited {a.proc.returncode}"
            parts.append(f"  {a.name} ({a.data_dir.name}, {state}) log tail:\n{log_tail(a.log)}")
        return "\n".join(parts)

    def wait_until(
        self,
        probe: Callable[[], T],
        ok: Callable[[T], bool],
        what: str,
        timeout: float = WAIT,
    ) -> T:
        """`tests.wait.until` every 0.1 s with the logs on failure; an agent exiting on its own
        fails it at once; an unanswered or refused request is "not yet"."""
        return wait.until(
            what,
            probe,
            ok,
            within=timeout,
            poll=POLL,
            retry=(OSError, RealnetError, ValueError, LookupError),  # URLError: OSError
            abort=self._crashed,
            context=self.logs,
        )

    def _crashed(self) -> str | None:
        """Which agent exited without being stopped, if one did."""
        crashed = [a for a in self.agents if not a.stopped and not a.running()]
        if crashed:
            return f"{crashed[0].name} exited with code {crashed[0].proc.returncode}"
        return None

    def wait_traffic(self, agents: Sequence[Agent], messages: int, what: str = "") -> None:
        """Wait until every one of `agents` has taken in `messages` more gossip messages than
        now (traffic flowed: a condition, where a fixed sleep would assume a rate)."""
        start = {a.name: a.agent_info()["messages"]["in"] for a in agents}
        for a in agents:
            self.wait_until(
                lambda a=a: a.agent_info()["messages"]["in"] - start[a.name],  # type: ignore[misc]
                lambda n: n >= messages,
                f"{messages} more messages into {a.name}" + (f" ({what})" if what else ""),
            )

    def wait_states(
        self, agent: Agent, expected: dict[str, str], what: str = "", timeout: float = WAIT
    ) -> dict[str, dict[str, Any]]:
        """Wait until `agent` shows each named member in the expected state; its members."""

        def ok(members: dict[str, dict[str, Any]]) -> bool:
            return all(members.get(n, {}).get("state") == s for n, s in expected.items())

        label = f"{agent.name} to see {expected}" + (f" ({what})" if what else "")
        return self.wait_until(agent.members, ok, label, timeout)


def _read_json(path: Path) -> dict[str, Any] | None:
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _signal_group(proc: subprocess.Popen[bytes], sig: int) -> None:
    """Signal the agent's process group (it leads its own session), else the process alone."""
    with contextlib.suppress(ProcessLookupError, PermissionError):
        os.killpg(proc.pid, sig)
        return
    with contextlib.suppress(ProcessLookupError):
        proc.send_signal(sig)


def kill_all(procs: Iterable[subprocess.Popen[Any]]) -> None:
    """SIGKILL each of `procs` still running and reap every one (a test's `finally`)."""
    for proc in procs:
        if proc.poll() is None:
            proc.kill()
        proc.wait()


def send_udp(addr: tuple[str, int], *datagrams: bytes) -> None:
    """Send raw datagrams to `addr` from a fresh, plain UDP socket."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as sock:
        for data in datagrams:
            sock.sendto(data, addr)
