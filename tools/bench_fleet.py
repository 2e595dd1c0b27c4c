"""Fleet benchmark: real sdrpeer agents side by side with HashiCorp Serf, at N = 10, 25 and 50.

Usage (root, for the iptables byte counters):
    python tools/bench_fleet.py [--sizes 10,25,50] [--idle 45] [--kills 5]
                                [--systems sdrpeer,serf] [--json out.json] [--quick]

How it works: for every N, Serf then sdrpeer (one fleet at a time, never both at once) run N
agents on 127.0.0.1, each agent in its own process, every agent joining robot-1:
- sdrpeer: `python -m sdrpeer agent --preset lan` with a cluster key and no robot file (the
  agents read the real machine's CPU and memory, so their metrics churn as the machine's load
  does), gossip on UDP port `31000 + k`, API on `32000 + k`;
- Serf (Debian's `serf` package, memberlist underneath): `serf agent -profile lan -encrypt KEY`
  on port `33000 + k` (UDP and TCP), RPC on `34000 + k`. Installed with apt when missing and
  possible; otherwise its rows are skipped with a loud line.

The same counting method on both sides: an iptables chain in OUTPUT (every loopback packet
passes it exactly once) with one counting rule per agent port and protocol: UDP by source port
(a datagram counts for the agent that sent it) and TCP both ways by the agent's port (Serf's
push-pull runs over TCP; its connections count for the listening agent). IP headers included.
The chain is removed afterwards, also on error.

Figures per system and N:
- join: robot-1 is started and answers, then the others at once; all started -> every API
  answers (sdrpeer `GET /healthz`, Serf an RPC handshake), and -> every agent sees N alive
  (sdrpeer: the time of each agent's (N-1)-th `member.join` in its event log; Serf: each
  agent's RPC event stream, opened as soon as its RPC answers, whose first event lists the
  members it already knows);
- idle, after the fleet settled: bytes/s per agent on the wire (mean, max), CPU % of one core
  (psutil user + system over the window; median, max), RSS (median, max);
- `--kills` times: SIGKILL of one agent (never robot-1) -> every other agent sees it dead
  (sdrpeer `member.dead` event times, Serf `member-failed` on the streams); then the agent is
  started again (same data dir) -> its API answers, -> it is fully started (sdrpeer: /healthz
  says `ready`, its deployment stack loaded; Serf: the same moment), and -> every other agent
  sees it alive
  (sdrpeer `member.alive`/`member.join`, Serf `member-join`); median and max over the kills;
- false suspicions and deaths: suspicions (sdrpeer `member.suspect` events, Serf's
  "Suspect X has failed" log lines) and deaths of agents outside their kill, over the whole run.

sdrpeer times come from the agents' own event logs (wall clock at the agent); Serf's from the
moment the benchmark reads the event off the RPC stream (a few hundred microseconds later).
Agents run from this checkout with its bytecode compiled first, as an installed robot's would be.
Every wait is bounded; agents are always stopped.
"""

from __future__ import annotations

import argparse
import asyncio
import base64
import compileall
import json
import os
import re
import shutil
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import msgpack
import psutil

ROOT = Path(__file__).resolve().parent.parent
CHAIN = "SDRFLEET"
SDRPEER_PORTS = (31000, 32000)
SERF_PORTS = (33000, 34000)
TARGETS = {
    "bytes_per_s_25": 2500.0,
    "bytes_per_s_50": 2500.0,
    "growth_50_over_10": 1.3,
    "detect_median_s_50": 2.0,
    "cpu_pct_50": 1.0,
    "rss_mib": 45.0,
    "restart_alive_median_s_25": 1.0,
    "api_start_s": 0.3,
    "join_after_api_s_50": 2.0,
}


def say(text: str) -> None:
    print(text, flush=True)


def median(xs: list[float]) -> float | None:
    return statistics.median(xs) if xs else None


# ------------------------------------------------------------------------------ iptables


class Counters:
    """Per-port byte counters in an iptables chain hooked into OUTPUT (root only)."""

    def __init__(self) -> None:
        self.ports: list[int] = []

    @staticmethod
    def _ipt(*args: str, check: bool = True) -> str:
        done = subprocess.run(
            ["iptables", "-w", *args], capture_output=True, text=True, check=False
        )
        if check and done.returncode != 0:
            raise RuntimeError(f"iptables {' '.join(args)}: {done.stderr.strip()}")
        return done.stdout

    def install(self, ports: list[int]) -> None:
        self.remove()
        self.ports = ports
        self._ipt("-N", CHAIN)
        self._ipt("-I", "OUTPUT", "-j", CHAIN)
        for p in ports:
            self._ipt("-A", CHAIN, "-p", "udp", "--sport", str(p))
            self._ipt("-A", CHAIN, "-p", "tcp", "--sport", str(p))
            self._ipt("-A", CHAIN, "-p", "tcp", "--dport", str(p))

    def read(self) -> dict[int, int]:
        """Bytes per agent port since install."""
        out = self._ipt("-L", CHAIN, "-v", "-n", "-x")
        per: dict[int, int] = dict.fromkeys(self.ports, 0)
        for line in out.splitlines():
            m = re.match(r"\s*\d+\s+(\d+)\s.*\b(?:udp|tcp) [sd]pt:(\d+)\s*$", line)
            if m is not None and int(m.group(2)) in per:
                per[int(m.group(2))] += int(m.group(1))
        return per

    def remove(self) -> None:
        self._ipt("-D", "OUTPUT", "-j", CHAIN, check=False)
        self._ipt("-F", CHAIN, check=False)
        self._ipt("-X", CHAIN, check=False)


# ------------------------------------------------------------------------------ fleets


@dataclass
class Observed:
    """What the benchmark learned of one fleet run."""

    system: str
    n: int
    join_api_s: float | None = None
    join_alive_s: float | None = None
    api_start_s: list[float] = field(default_factory=list)
    ready_start_s: list[float] = field(default_factory=list)
    bytes_per_s: list[float] = field(default_factory=list)
    cpu_pct: list[float] = field(default_factory=list)
    rss_mib: list[float] = field(default_factory=list)
    detect_s: list[float] = field(default_factory=list)
    detect_all_s: list[list[float]] = field(default_factory=list)
    restart_alive_s: list[float] = field(default_factory=list)
    false_suspicions: int = 0
    false_deaths: int = 0
    notes: list[str] = field(default_factory=list)
    marks: dict[str, Any] = field(default_factory=dict)
    """When the idle window and each kill happened (wall clock), for a post-mortem."""


class Fleet:
    """N agents of one system on loopback; subclasses start them and read their views."""

    system = ""
    ports: tuple[int, int] = (0, 0)

    def __init__(self, n: int, workdir: Path) -> None:
        self.n = n
        self.workdir = workdir
        self.procs: dict[int, subprocess.Popen[bytes]] = {}
        self.killed: list[tuple[int, float, float | None]] = []
        """(robot index, kill time, time it was seen alive by all again)."""

    def name(self, k: int) -> str:
        return f"robot-{k}"

    def gossip_port(self, k: int) -> int:
        return self.ports[0] + k

    def api_port(self, k: int) -> int:
        return self.ports[1] + k

    def spawn(self, k: int) -> None:
        raise NotImplementedError

    async def api_ready(self, k: int) -> bool:
        raise NotImplementedError

    async def fully_ready(self, k: int) -> bool:
        """Whether everything the agent runs is up (the API may answer before)."""
        return await self.api_ready(k)

    async def alive_times(self, t0: float, within: float) -> list[float] | None:
        """When each agent saw all N alive (wall clock), or None past the timeout."""
        raise NotImplementedError

    async def seen(self, subject: int, kind: str, after: float, within: float) -> list[float]:
        """Times at which every other agent saw `subject` dead ("dead") or alive ("alive")
        after `after`; a shorter list when some did not within the timeout."""
        raise NotImplementedError

    async def false_alarms(self) -> tuple[int, int]:
        """(suspicions, deaths) of agents outside their kill windows."""
        raise NotImplementedError

    async def start_all(self) -> float:
        """Start robot-1, and once it answers the others at once (a Serf agent whose seed is
        not listening yet exits); the time the last process was started."""
        self.spawn(1)
        if not await _wait_all(self.api_ready, [1], within=30, every=0.01):
            raise RuntimeError(f"{self.system}: robot-1 did not answer within 30 s")
        for k in range(2, self.n + 1):
            self.spawn(k)
        return time.time()

    def kill(self, k: int) -> float:
        proc = self.procs[k]
        t = time.time()
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)
        return t

    def stop(self) -> None:
        for proc in self.procs.values():
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        deadline = time.monotonic() + 10
        for proc in self.procs.values():
            try:
                proc.wait(timeout=max(0.1, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)

    def pids(self) -> list[int]:
        return [p.pid for p in self.procs.values() if p.poll() is None]

    def in_kill_window(self, k: int, t: float) -> bool:
        return any(v == k and t0 <= t <= (t1 or float("inf")) + 1.0 for v, t0, t1 in self.killed)


async def _http_get(port: int, path: str, within: float = 5.0) -> Any:
    """GET http://127.0.0.1:port/path -> decoded JSON (raises on any failure)."""
    async with asyncio.timeout(within):
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        try:
            writer.write(
                f"GET {path} HTTP/1.1\r\nHost: 127.0.0.1\r\nConnection: close\r\n\r\n".encode()
            )
            raw = await reader.read()
        finally:
            writer.close()
    head, _, body = raw.partition(b"\r\n\r\n")
    if not head.startswith(b"HTTP/1.1 200"):
        raise RuntimeError(head[:40])
    if b"chunked" in head.lower():
        body = _unchunk(body)
    return json.loads(body)


def _unchunk(body: bytes) -> bytes:
    out = b""
    while body:
        size_line, _, rest = body.partition(b"\r\n")
        size = int(size_line, 16)
        if size == 0:
            break
        out += rest[:size]
        body = rest[size + 2 :]
    return out


class SdrpeerFleet(Fleet):
    system = "sdrpeer"
    ports = SDRPEER_PORTS

    def __init__(self, n: int, workdir: Path) -> None:
        super().__init__(n, workdir)
        from sdrpeer.gossip.wire import Keyring  # noqa: PLC0415 - the benchmark's own import

        self.key = workdir / "cluster.key"
        self.key.write_text(Keyring.format_key(Keyring.generate()) + "\n")
        self.key.chmod(0o600)

    def spawn(self, k: int) -> None:
        data = self.workdir / self.name(k)
        data.mkdir(exist_ok=True)
        cmd = [
            sys.executable,
            "-m",
            "sdrpeer",
            "agent",
            "--name",
            self.name(k),
            "--bind",
            f"127.0.0.1:{self.gossip_port(k)}",
            "--api",
            f"127.0.0.1:{self.api_port(k)}",
            "--key-file",
            str(self.key),
            "--preset",
            "lan",
            "--data-dir",
            str(data),
            "--log-level",
            "warning",
        ]
        seed = 1 if k != 1 else None
        if k == 1 and self.procs.get(1) is not None and self.procs[1].poll() is not None:
            seed = 2
        if seed is not None:
            cmd += ["--join", f"127.0.0.1:{self.gossip_port(seed)}"]
        log = (data / "agent.log").open("ab")
        env = {k: v for k, v in os.environ.items() if k != "PYTHONDONTWRITEBYTECODE"}
        self.procs[k] = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True, env=env
        )

    async def api_ready(self, k: int) -> bool:
        try:
            await _http_get(self.api_port(k), "/healthz", within=1.0)
        except (OSError, RuntimeError, TimeoutError, ValueError):
            return False
        return True

    async def fully_ready(self, k: int) -> bool:
        try:
            doc = await _http_get(self.api_port(k), "/healthz", within=1.0)
        except (OSError, RuntimeError, TimeoutError, ValueError):
            return False
        return bool(doc.get("ready", True))

    async def events(self, k: int) -> list[dict[str, Any]]:
        out: list[dict[str, Any]] = []
        since = 0
        for _ in range(100):
            batch = await _http_get(self.api_port(k), f"/v1/events?since={since}&limit=10000")
            if not batch:
                break
            out += batch
            since = batch[-1]["id"]
        return out

    async def _all_events(self, exclude: int | None = None) -> dict[int, list[dict[str, Any]]]:
        ks = [k for k in range(1, self.n + 1) if k != exclude]
        got = await asyncio.gather(*(self.events(k) for k in ks), return_exceptions=True)
        return {k: g for k, g in zip(ks, got, strict=True) if isinstance(g, list)}

    async def alive_times(self, t0: float, within: float) -> list[float] | None:
        deadline = time.monotonic() + within
        while time.monotonic() < deadline:
            times = []
            for evs in (await self._all_events()).values():
                joined = sorted(
                    e["ts"] for e in evs if e["kind"] == "member.join" and e["ts"] >= t0 - 5
                )
                if len(joined) >= self.n - 1:
                    times.append(joined[self.n - 2])
            if len(times) == self.n:
                return times
            await asyncio.sleep(1.0)
        return None

    async def seen(self, subject: int, kind: str, after: float, within: float) -> list[float]:
        kinds = {"dead": ("member.dead",), "alive": ("member.alive", "member.join")}[kind]
        name = self.name(subject)
        deadline = time.monotonic() + within
        times: list[float] = []
        while time.monotonic() < deadline:
            times = []
            for evs in (await self._all_events(exclude=subject)).values():
                hits = [
                    e["ts"]
                    for e in evs
                    if e["kind"] in kinds and e["robot"] == name and e["ts"] >= after
                ]
                if hits:
                    times.append(min(hits))
            if len(times) == self.n - 1:
                break
            await asyncio.sleep(0.5)
        return times

    async def false_alarms(self) -> tuple[int, int]:
        suspicions = deaths = 0
        for evs in (await self._all_events()).values():
            for e in evs:
                if e["kind"] not in ("member.suspect", "member.dead"):
                    continue
                k = int(e["robot"].rsplit("-", 1)[1])
                if self.in_kill_window(k, e["ts"]):
                    continue
                if e["kind"] == "member.suspect":
                    suspicions += 1
                else:
                    deaths += 1
        return suspicions, deaths


class SerfStream:
    """One Serf agent's RPC connection with a member event stream; events timestamped here."""

    def __init__(self) -> None:
        self.events: list[tuple[float, str, list[str]]] = []
        self._task: asyncio.Task[None] | None = None
        self._writer: asyncio.StreamWriter | None = None

    async def open(self, port: int) -> None:
        reader, writer = await asyncio.open_connection("127.0.0.1", port)
        self._writer = writer
        unpacker = msgpack.Unpacker(raw=False)

        async def next_obj() -> Any:
            while True:
                try:
                    return next(unpacker)
                except StopIteration:
                    data = await reader.read(65536)
                    if not data:
                        raise ConnectionError("serf rpc closed") from None
                    unpacker.feed(data)

        writer.write(msgpack.packb({"Command": "handshake", "Seq": 0}))
        writer.write(msgpack.packb({"Version": 1}))
        await writer.drain()
        head = await next_obj()
        if head.get("Error"):
            raise ConnectionError(head["Error"])
        writer.write(msgpack.packb({"Command": "stream", "Seq": 1}))
        writer.write(msgpack.packb({"Type": "member-join,member-failed,member-leave"}))
        await writer.drain()
        await next_obj()  # the stream's acknowledgement

        async def pump() -> None:
            while True:
                obj = await next_obj()
                if isinstance(obj, dict) and "Event" in obj:
                    names = [m["Name"] for m in obj.get("Members", [])]
                    self.events.append((time.time(), obj["Event"], names))

        self._task = asyncio.create_task(pump())

    def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
        if self._writer is not None:
            self._writer.close()


class SerfFleet(Fleet):
    system = "serf"
    ports = SERF_PORTS

    def __init__(self, n: int, workdir: Path) -> None:
        super().__init__(n, workdir)
        self.key = base64.b64encode(os.urandom(32)).decode()
        self.streams: dict[int, SerfStream] = {}

    def spawn(self, k: int) -> None:
        data = self.workdir / self.name(k)
        data.mkdir(exist_ok=True)
        cmd = [
            "serf",
            "agent",
            f"-node={self.name(k)}",
            f"-bind=127.0.0.1:{self.gossip_port(k)}",
            f"-rpc-addr=127.0.0.1:{self.api_port(k)}",
            f"-encrypt={self.key}",
            "-profile=lan",
            "-log-level=info",
        ]
        if k != 1:
            cmd.append(f"-join=127.0.0.1:{self.gossip_port(1)}")
        log = (data / "agent.log").open("ab")
        self.procs[k] = subprocess.Popen(
            cmd, stdout=log, stderr=subprocess.STDOUT, start_new_session=True
        )
        old = self.streams.pop(k, None)
        if old is not None:
            old.close()

    async def api_ready(self, k: int) -> bool:
        if k in self.streams:
            return True
        stream = SerfStream()
        try:
            async with asyncio.timeout(1.0):
                await stream.open(self.api_port(k))
        except (OSError, ConnectionError, TimeoutError):
            stream.close()
            return False
        self.streams[k] = stream
        return True

    async def alive_times(self, t0: float, within: float) -> list[float] | None:
        deadline = time.monotonic() + within
        polled: dict[int, float] = {}
        while time.monotonic() < deadline:
            times = []
            for k, stream in self.streams.items():
                known: set[str] = set()
                for t, kind, names in stream.events:
                    if kind == "member-join":
                        known.update(names)
                    if len(known) >= self.n:
                        times.append(t)
                        break
                else:
                    if k in polled:
                        times.append(polled[k])
                    elif (  # a busy agent may drop stream events: ask it (a poll)
                        time.monotonic() > deadline - within + 10
                        and await _serf_alive(self.api_port(k)) >= self.n
                    ):
                        polled[k] = time.time()
            if len(times) == self.n:
                return times
            await asyncio.sleep(0.2)
        return None

    async def seen(self, subject: int, kind: str, after: float, within: float) -> list[float]:
        want = {"dead": "member-failed", "alive": "member-join"}[kind]
        name = self.name(subject)
        deadline = time.monotonic() + within
        times: list[float] = []
        while time.monotonic() < deadline:
            times = []
            for k, stream in self.streams.items():
                if k == subject:
                    continue
                hits = [t for t, e, names in stream.events if e == want and name in names]
                hits = [t for t in hits if t >= after]
                if hits:
                    times.append(min(hits))
            if len(times) == self.n - 1:
                break
            await asyncio.sleep(0.2)
        return times

    async def false_alarms(self) -> tuple[int, int]:
        suspicions = deaths = 0
        pattern = re.compile(r"Suspect (robot-\d+) has failed")
        for k in range(1, self.n + 1):
            log = self.workdir / self.name(k) / "agent.log"
            for line in log.read_text(errors="replace").splitlines():
                m = pattern.search(line)
                if m is not None:
                    t = _serf_log_time(line)
                    victim = int(m.group(1).rsplit("-", 1)[1])
                    if t is None or not self.in_kill_window(victim, t):
                        suspicions += 1
        for stream in self.streams.values():
            for t, e, names in stream.events:
                if e == "member-failed":
                    for name in names:
                        if not self.in_kill_window(int(name.rsplit("-", 1)[1]), t):
                            deaths += 1
        return suspicions, deaths

    def stop(self) -> None:
        for stream in self.streams.values():
            stream.close()
        super().stop()


async def _serf_alive(port: int) -> int:
    """How many members one Serf agent lists as alive (an RPC `members` call), 0 on failure."""
    try:
        async with asyncio.timeout(2.0):
            reader, writer = await asyncio.open_connection("127.0.0.1", port)
            try:
                unpacker = msgpack.Unpacker(raw=False)
                writer.write(msgpack.packb({"Command": "handshake", "Seq": 0}))
                writer.write(msgpack.packb({"Version": 1}))
                writer.write(msgpack.packb({"Command": "members", "Seq": 1}))
                objs: list[Any] = []
                while len(objs) < 3:
                    data = await reader.read(65536)
                    if not data:
                        return 0
                    unpacker.feed(data)
                    objs += list(unpacker)
            finally:
                writer.close()
    except (OSError, TimeoutError, ValueError):
        return 0
    return sum(1 for m in objs[2].get("Members", []) if m.get("Status") == "alive")


def _serf_log_time(line: str) -> float | None:
    m = re.search(r"(\d{4}/\d\d/\d\d \d\d:\d\d:\d\d)", line)
    if m is None:
        return None
    return time.mktime(time.strptime(m.group(1), "%Y/%m/%d %H:%M:%S"))


# ------------------------------------------------------------------------------ one run


async def _wait_all(
    check: Callable[[int], Awaitable[bool]], ks: list[int], within: float, every: float
) -> dict[int, float]:
    """Poll `check(k)` for every k until it holds; when it first held, per k (wall clock)."""
    done: dict[int, float] = {}
    deadline = time.monotonic() + within
    while len(done) < len(ks) and time.monotonic() < deadline:
        todo = [k for k in ks if k not in done]
        results = await asyncio.gather(*(check(k) for k in todo))
        now = time.time()
        for k, ok in zip(todo, results, strict=True):
            if ok:
                done[k] = now
        if len(done) < len(ks):
            await asyncio.sleep(every)
    return done


async def run_fleet(fleet: Fleet, args: argparse.Namespace, counters: Counters | None) -> Observed:
    n = fleet.n
    obs = Observed(fleet.system, n)
    ks = list(range(1, n + 1))
    if counters is not None:
        counters.install([fleet.gossip_port(k) for k in ks])
    t_started = await fleet.start_all()
    ready = await _wait_all(fleet.api_ready, ks, within=60, every=0.02)
    if len(ready) < n:
        obs.notes.append(f"only {len(ready)} of {n} APIs answered within 60 s")
        return obs
    obs.join_api_s = max(ready.values()) - t_started
    alive = await fleet.alive_times(t_started, within=90)
    if alive is None:
        obs.notes.append("the fleet did not see all alive within 90 s")
        return obs
    obs.join_alive_s = max(alive) - t_started
    say(f"  {fleet.system} N={n}: APIs {obs.join_api_s:.2f} s, all alive {obs.join_alive_s:.2f} s")

    await asyncio.sleep(args.settle)
    pids = fleet.pids()
    procs = [psutil.Process(p) for p in pids]
    cpu0 = [sum(p.cpu_times()[:2]) for p in procs]
    bytes0 = counters.read() if counters is not None else {}
    t0, t_idle0 = time.monotonic(), time.time()
    await asyncio.sleep(args.idle)
    dt, t_idle1 = time.monotonic() - t0, time.time()
    cpu1 = [sum(p.cpu_times()[:2]) for p in procs]
    bytes1 = counters.read() if counters is not None else {}
    obs.cpu_pct = [100 * (b - a) / dt for a, b in zip(cpu0, cpu1, strict=True)]
    obs.rss_mib = [p.memory_info().rss / 2**20 for p in procs]
    obs.bytes_per_s = [(bytes1[p] - bytes0[p]) / dt for p in bytes1]
    if obs.bytes_per_s:
        say(
            f"  idle {dt:.0f} s: {statistics.mean(obs.bytes_per_s):,.0f} B/s per agent, "
            f"cpu {median(obs.cpu_pct):.2f} %, rss {median(obs.rss_mib):.1f} MiB"
        )

    for i in range(args.kills):
        victim = 2 + (i * 7) % (n - 1)
        t_kill = fleet.kill(victim)
        seen_dead = await fleet.seen(victim, "dead", t_kill, within=60)
        t_back = time.time()
        fleet.killed.append((victim, t_kill, None))
        if len(seen_dead) < n - 1:
            obs.notes.append(f"kill {i + 1}: only {len(seen_dead)} of {n - 1} saw it dead")
        else:
            obs.detect_s.append(max(seen_dead) - t_kill)
            obs.detect_all_s.append(sorted(round(t - t_kill, 3) for t in seen_dead))
        await asyncio.sleep(1.0)
        t_restart = time.time()
        fleet.spawn(victim)
        up = await _wait_all(fleet.api_ready, [victim], within=30, every=0.005)
        if victim in up:
            obs.api_start_s.append(up[victim] - t_restart)
        whole = await _wait_all(fleet.fully_ready, [victim], within=30, every=0.005)
        if victim in whole:
            obs.ready_start_s.append(whole[victim] - t_restart)
        seen_alive = await fleet.seen(victim, "alive", t_restart, within=60)
        t_back = max(seen_alive) if seen_alive else time.time()
        fleet.killed[-1] = (victim, t_kill, t_back)
        if len(seen_alive) < n - 1:
            obs.notes.append(f"restart {i + 1}: only {len(seen_alive)} of {n - 1} saw it alive")
        else:
            obs.restart_alive_s.append(max(seen_alive) - t_restart)
        say(
            f"  kill {i + 1} ({fleet.name(victim)}): dead everywhere "
            f"{(max(seen_dead) - t_kill) if seen_dead else float('nan'):.2f} s, "
            f"alive everywhere {(t_back - t_restart):.2f} s after restart"
        )
        await asyncio.sleep(args.gap)
    obs.false_suspicions, obs.false_deaths = await fleet.false_alarms()
    if args.keep and isinstance(fleet, SdrpeerFleet):  # each agent's event log, for a post-mortem
        for k, evs in (await fleet._all_events()).items():
            (fleet.workdir / fleet.name(k) / "events.json").write_text(json.dumps(evs))
    obs.marks = {"idle": [t_idle0, t_idle1], "kills": [[v, a, b] for v, a, b in fleet.killed]}
    return obs


async def run_all(args: argparse.Namespace) -> list[Observed]:
    # An installed robot has its bytecode compiled (pip does it); a checkout under
    # PYTHONDONTWRITEBYTECODE would compile every module at every start instead.
    compileall.compile_dir(ROOT / "sdrpeer", quiet=1)
    counters = Counters() if os.geteuid() == 0 and shutil.which("iptables") else None
    if counters is None:
        say("!!! not root or no iptables: traffic figures are SKIPPED (run as root)")
    systems = args.systems.split(",")
    if "serf" in systems and not ensure_serf():
        say("!!! serf is not installed and cannot be (apt-get install serf): Serf rows SKIPPED")
        systems.remove("serf")
    results: list[Observed] = []
    try:
        for n in args.sizes:
            for system in systems:
                with tempfile.TemporaryDirectory(prefix=f"fleet-{system}-{n}-") as tmp:
                    cls = SerfFleet if system == "serf" else SdrpeerFleet
                    fleet: Fleet = cls(n, Path(tmp))
                    try:
                        results.append(await run_fleet(fleet, args, counters))
                    finally:
                        fleet.stop()
                        if args.keep:
                            dest = Path(args.keep) / f"{system}-{n}"
                            shutil.rmtree(dest, ignore_errors=True)
                            shutil.copytree(tmp, dest)
                await asyncio.sleep(2.0)
    finally:
        if counters is not None:
            counters.remove()
    return results


def ensure_serf() -> bool:
    if shutil.which("serf"):
        return True
    if os.geteuid() != 0 or not shutil.which("apt-get"):
        return False
    say("== installing serf (apt-get install serf)")
    subprocess.run(["apt-get", "install", "-y", "-qq", "serf"], capture_output=True, check=False)
    return shutil.which("serf") is not None


# ------------------------------------------------------------------------------ report


def summary(o: Observed) -> dict[str, Any]:
    def r(x: float | None, nd: int = 3) -> float | None:
        return None if x is None else round(x, nd)

    return {
        "system": o.system,
        "n": o.n,
        "join_api_s": r(o.join_api_s),
        "join_alive_s": r(o.join_alive_s),
        "join_alive_after_api_s": r(
            None
            if o.join_alive_s is None or o.join_api_s is None
            else o.join_alive_s - o.join_api_s
        ),
        "bytes_per_s_mean": r(statistics.mean(o.bytes_per_s), 1) if o.bytes_per_s else None,
        "bytes_per_s_max": r(max(o.bytes_per_s), 1) if o.bytes_per_s else None,
        "cpu_pct_median": r(median(o.cpu_pct)),
        "cpu_pct_max": r(max(o.cpu_pct)) if o.cpu_pct else None,
        "rss_mib_median": r(median(o.rss_mib), 1),
        "rss_mib_max": r(max(o.rss_mib), 1) if o.rss_mib else None,
        "detect_median_s": r(median(o.detect_s)),
        "detect_max_s": r(max(o.detect_s)) if o.detect_s else None,
        "detect_s": [r(x) for x in o.detect_s],
        "detect_per_observer_s": o.detect_all_s,
        "restart_alive_median_s": r(median(o.restart_alive_s)),
        "restart_alive_max_s": r(max(o.restart_alive_s)) if o.restart_alive_s else None,
        "restart_alive_s": [r(x) for x in o.restart_alive_s],
        "api_start_median_s": r(median(o.api_start_s)),
        "api_start_s": [r(x) for x in o.api_start_s],
        "ready_start_median_s": r(median(o.ready_start_s)),
        "false_suspicions": o.false_suspicions,
        "false_deaths": o.false_deaths,
        "notes": o.notes,
        "marks": o.marks,
    }


ROWS = (
    ("join: started -> all APIs answer (s)", "join_api_s", "{:.2f}"),
    ("join: started -> all see N alive (s)", "join_alive_s", "{:.2f}"),
    ("join: last API -> all see N alive (s)", "join_alive_after_api_s", "{:.2f}"),
    ("idle bytes/s per agent, mean", "bytes_per_s_mean", "{:,.0f}"),
    ("idle bytes/s per agent, max", "bytes_per_s_max", "{:,.0f}"),
    ("idle CPU % per agent, median", "cpu_pct_median", "{:.2f}"),
    ("idle CPU % per agent, max", "cpu_pct_max", "{:.2f}"),
    ("RSS MiB, median", "rss_mib_median", "{:.1f}"),
    ("RSS MiB, max", "rss_mib_max", "{:.1f}"),
    ("kill -9 -> all see dead, median (s)", "detect_median_s", "{:.2f}"),
    ("kill -9 -> all see dead, max (s)", "detect_max_s", "{:.2f}"),
    ("restart -> all see alive, median (s)", "restart_alive_median_s", "{:.2f}"),
    ("restart -> all see alive, max (s)", "restart_alive_max_s", "{:.2f}"),
    ("process start -> API answers, median (s)", "api_start_median_s", "{:.3f}"),
    ("process start -> fully started, median (s)", "ready_start_median_s", "{:.3f}"),
    ("false suspicions", "false_suspicions", "{}"),
    ("false deaths", "false_deaths", "{}"),
)


def fmt(value: Any, spec: str) -> str:
    return "-" if value is None else spec.format(value)


def table(rows: list[dict[str, Any]]) -> str:
    lines = []
    for n in sorted({r["n"] for r in rows}):
        ours = next((r for r in rows if r["n"] == n and r["system"] == "sdrpeer"), None)
        serf = next((r for r in rows if r["n"] == n and r["system"] == "serf"), None)
        lines.append(f"\nN = {n}")
        lines.append(f"  {'figure':44} {'sdrpeer':>10} {'serf':>10} {'ratio':>8}")
        for label, key, spec in ROWS:
            a = None if ours is None else ours.get(key)
            b = None if serf is None else serf.get(key)
            ratio = f"{a / b:.2f}x" if isinstance(a, float) and isinstance(b, float) and b else ""
            lines.append(f"  {label:44} {fmt(a, spec):>10} {fmt(b, spec):>10} {ratio:>8}")
        for r in (ours, serf):
            if r is not None:
                for note in r["notes"]:
                    lines.append(f"  ! {r['system']}: {note}")
        if (
            ours
            and serf
            and ours["bytes_per_s_mean"]
            and serf["bytes_per_s_mean"]
            and ours["detect_median_s"]
            and serf["detect_median_s"]
        ):
            a = ours["bytes_per_s_mean"] * ours["detect_median_s"]
            b = serf["bytes_per_s_mean"] * serf["detect_median_s"]
            lines.append(f"  {'traffic x detection (B)':44} {a:>10,.0f} {b:>10,.0f} {a / b:>7.2f}x")
    return "\n".join(lines)


def targets(rows: list[dict[str, Any]]) -> list[str]:
    ours = {r["n"]: r for r in rows if r["system"] == "sdrpeer"}
    out = []

    def check(label: str, value: float | None, limit: float) -> None:
        if value is None:
            out.append(f"  {label}: not measured")
        else:
            verdict = "met" if value <= limit else "NOT met"
            out.append(f"  {label}: {value:.3g} (target <= {limit:g}) {verdict}")

    for n in (25, 50):
        if n in ours:
            check(f"bytes/s per agent at N={n}", ours[n]["bytes_per_s_mean"], 2500)
    if 10 in ours and 50 in ours and ours[10]["bytes_per_s_mean"] and ours[50]["bytes_per_s_mean"]:
        check(
            "N=50 / N=10 traffic", ours[50]["bytes_per_s_mean"] / ours[10]["bytes_per_s_mean"], 1.3
        )
    if 50 in ours:
        check("detection median at N=50 (s)", ours[50]["detect_median_s"], 2.0)
        check("false deaths at N=50", ours[50]["false_deaths"], 0)
        check("idle CPU % at N=50 (median)", ours[50]["cpu_pct_median"], 1.0)
        check("N=50 last API -> all alive (s)", ours[50]["join_alive_after_api_s"], 2.0)
    for n, r in sorted(ours.items()):
        check(f"RSS MiB at N={n} (max)", r["rss_mib_max"], 45)
    if 25 in ours:
        check("restart -> all alive median at N=25 (s)", ours[25]["restart_alive_median_s"], 1.0)
    starts = [x for r in ours.values() for x in r["api_start_s"] if x is not None]
    check("process start -> API answers, median (s)", median(starts), 0.3)
    return out


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--sizes", default="10,25,50")
    p.add_argument("--systems", default="sdrpeer,serf")
    p.add_argument("--idle", type=float, default=45.0, help="idle window (s)")
    p.add_argument("--settle", type=float, default=10.0, help="wait after the join (s)")
    p.add_argument("--kills", type=int, default=5)
    p.add_argument("--gap", type=float, default=3.0, help="wait between kills (s)")
    p.add_argument("--json", type=Path, help="write every figure here")
    p.add_argument("--keep", help="copy each fleet's data dirs and logs here")
    p.add_argument("--quick", action="store_true", help="N=5, 5 s idle, 1 kill")
    args = p.parse_args(argv)
    if args.quick:
        args.sizes, args.idle, args.settle, args.kills, args.gap = "5", 5.0, 2.0, 1, 1.0
    args.sizes = [int(x) for x in str(args.sizes).split(",")]
    t0 = time.monotonic()
    observed = asyncio.run(run_all(args))
    rows = [summary(o) for o in observed]
    say(table(rows))
    say("\nTargets (sdrpeer):")
    for line in targets(rows):
        say(line)
    say(f"\n({time.monotonic() - t0:.0f} s, load average {os.getloadavg()[0]:.1f})")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        doc = {"quick": args.quick, "idle_s": args.idle, "kills": args.kills, "runs": rows}
        doc["load_average_end"] = os.getloadavg()
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
