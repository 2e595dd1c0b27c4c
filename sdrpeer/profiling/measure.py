"""`sdrpeer profile pkg.mod:Class`: measure what one component costs, in a real host process.

How it works: `run_profile` drives a `_Session` through start, wire, measure and stop. It starts
the component the way an agent does: the `python` launcher
(sdrpeer.launch.launchers) builds the `python -m sdrpeer.host` command, the host inherits one end
of a socket pair as its control channel (sdrpeer.control.agent_side.ControlChannel on our end) and
reports `hello` and `state INACTIVE`. Every OutPort is then connected (a `connect` command) to
an in-process `DataServer` that counts and discards, so frames really cross a socket; every
InPort is fed by an in-process data-plane `Connection` at `input_rate` Hz with values from an
input source (`make_source`: synthetic images for `image`, plausible maps for `alarm`, `pose`
and `odometry`, a generic map otherwise, or `--input port=FILE`: a recorded file of concatenated
msgpack values, replayed in a loop). The host is activated and, for `seconds`, its CPU % (of one
core) and RSS are sampled with psutil every `sample_interval` seconds, while its heartbeats
(every 0.5 s) give the port counters. Rates are counter differences between the first and the
last heartbeat of the window over the host's own heartbeat timestamps. Finally the host is
deactivated and told to exit (killed if it has not after 5 s).

Output (YAML, written by `write_profile`; the system files of the allocation issue read it):

    component: Camera                      # the class name from the host's hello
    target: components.camera:Camera       # what was launched (python launcher)
    params: {rate: 10.0, ...}              # every param's value in the run (from hello)
    seconds: 10.0                          # the measured window, ACTIVE throughout
    cpu: {mean_pct: 4.2, peak_pct: 10.0, samples: 100}   # % of one core, psutil samples
    memory: {peak_rss: 31457280, peak_rss_human: 31.46MB, mean_rss: ...}  # bytes; MB = 10^6
    ports:
      image: {direction: out, frames_per_s: 10.0, bytes_per_s: 192370.0}
    inputs: {}                             # in-port -> input source used (e.g. image:160x120)
    input_rate: 10.0                       # Hz at which each in-port was fed
    measured_at: '2025-01-01T12:00:00+00:00'
    host: {hostname, platform, machine, python, cpus, memory_total}

`bytes_per_s` counts wire bytes (msgpack frames, overhead included): for an OutPort the host's
`bytes_out` counter, for an InPort the bytes our feeding connection wrote to it (the host's
`bytes_in` counts raw bytes values only). `frames_per_s` of an InPort counts frames the host
received. `peak_pct` is the highest 0.1 s sample: the kernel counts CPU time in 10 ms ticks, so
a light component's samples read 0 or about 10 %; `mean_pct` is the figure to plan with. The
human size uses sdrpeer.units (powers of 1000), so `parse_size` reads it back.
"""

from __future__ import annotations

import asyncio
import contextlib
import datetime as dt
import os
import platform
import shutil
import socket
import sys
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import psutil
import yaml

from sdrpeer.control.agent_side import ControlChannel
from sdrpeer.control.messages import (
    Activate,
    Conn,
    Connect,
    Deactivate,
    Exit,
    Heartbeat,
    Hello,
    Report,
    State,
)
from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.errors import ProfileError, SdrpeerError
from sdrpeer.launch.launchers import get_launcher, host_env
from sdrpeer.monitor.procstats import ProcessTreeMeter
from sdrpeer.profiling.inputs import GENERATORS, Source, make_source
from sdrpeer.runtime.launch import private_dir
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.units import format_size
from sdrpeer.vocabulary import LifecycleState

__all__ = [
    "GENERATORS",
    "ProfileError",
    "ProfileRequest",
    "make_source",
    "run_profile",
    "write_profile",
]

HEARTBEAT = 0.5


@dataclass(frozen=True)
class ProfileRequest:
    """What to profile and how."""

    target: str
    """`package.module:Class`."""
    seconds: float = 10.0
    """Length of the measured window (>= 1: rates need two heartbeats)."""
    params: dict[str, str] = field(default_factory=dict)
    """Params as `--param k=v` strings."""
    inputs: dict[str, str] = field(default_factory=dict)
    """InPort -> input source (a generator name or a msgpack file); others get the default."""
    input_rate: float = 10.0
    """Frames per second fed to each InPort."""
    sample_interval: float = 0.1
    """Seconds between two CPU/RSS samples."""
    start_timeout: float = 15.0
    """Seconds the host may take to report INACTIVE."""


class _Sink:
    """An InPort stand-in on our data server: takes every frame and forgets it."""

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Discard one frame."""

    def refuse(self) -> None:
        """Nothing to do: the server logs it."""


Beat = tuple[float, dict[str, dict[str, int]], dict[str, int]]
"""One heartbeat: host time, port counters, bytes our feeders had written by then."""


def port_rates(
    beats: list[tuple[float, dict[str, dict[str, int]], dict[str, int]]],
    directions: Mapping[str, str],
) -> dict[str, dict[str, Any]]:
    """Per-port frames/s and bytes/s between the first and the last heartbeat."""
    if len(beats) < 2:
        raise ProfileError(f"only {len(beats)} heartbeat(s) in the window: measure longer")
    (t0, c0, s0), (t1, c1, s1) = beats[0], beats[-1]
    span = t1 - t0
    out: dict[str, dict[str, Any]] = {}
    for name, direction in directions.items():
        a, b = c0.get(name, {}), c1.get(name, {})
        key = "frames_in" if direction == "in" else "frames_out"
        frames = b.get(key, 0) - a.get(key, 0)
        if direction == "in":
            sent = s1.get(name, 0) - s0.get(name, 0)
        else:
            sent = b.get("bytes_out", 0) - a.get("bytes_out", 0)
        out[name] = {
            "direction": direction,
            "frames_per_s": round(frames / span, 2),
            "bytes_per_s": round(sent / span, 1),
        }
    return out


def host_info() -> dict[str, Any]:
    """Where the measurement was taken."""
    return {
        "hostname": socket.gethostname(),
        "platform": platform.platform(),
        "machine": platform.machine(),
        "python": platform.python_version(),
        "cpus": os.cpu_count(),
        "memory_total": psutil.virtual_memory().total,
    }


async def _feed(conn: Connection, source: Source, rate: float) -> None:
    """Offer one value per period to `conn` (a grid of deadlines, never drifting)."""
    loop = asyncio.get_running_loop()
    start = loop.time()
    seq = 0
    while True:
        seq += 1
        conn.offer(source(seq, (seq - 1) / rate))
        await asyncio.sleep(max(0.0, start + seq / rate - loop.time()))


class _Session:
    """One host under measurement: start, wire, measure, stop (always in that order)."""

    def __init__(self, req: ProfileRequest) -> None:
        loop = asyncio.get_running_loop()
        self.req = req
        self.hello: asyncio.Future[Hello] = loop.create_future()
        self.inactive: asyncio.Future[None] = loop.create_future()
        self.error: str | None = None
        self.beats: list[Beat] = []
        self.recording = False
        self.feeders: dict[str, Connection] = {}
        self.feeds: list[asyncio.Task[None]] = []
        self.inputs: dict[str, str] = {}
        self.run_dir = private_dir("profile")
        self.log_path = self.run_dir / "host.log"
        self.server = DataServer(lambda name: _Sink(), unix_path=str(self.run_dir / "sink.sock"))
        self.proc: asyncio.subprocess.Process | None = None
        self.channel: ControlChannel | None = None

    def log_tail(self) -> str:
        """The end of what the host wrote to stderr."""
        text = self.log_path.read_text(errors="replace") if self.log_path.exists() else ""
        return text[-2000:]

    async def start(self) -> Hello:
        """Launch the host like an agent; its hello once it reported INACTIVE."""
        req = self.req
        ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
        argv = get_launcher("python").command(req.target, dict(req.params), python=sys.executable)
        env = {k: v for k, v in os.environ.items() if not k.startswith("SDRPEER_")}
        env |= host_env(
            instance="profile",
            control_fd=theirs.fileno(),
            data_host="127.0.0.1",
            run_dir=str(self.run_dir),
        )
        with self.log_path.open("wb") as log:
            self.proc = await asyncio.create_subprocess_exec(
                *argv,
                pass_fds=(theirs.fileno(),),
                env=env,
                stdin=asyncio.subprocess.DEVNULL,
                stdout=log,
                stderr=log,
            )
        theirs.close()
        self.channel = ControlChannel(ours, self._report, self._closed, name="profile")
        await self.channel.open()
        await self.server.start()
        try:
            async with asyncio.timeout(req.start_timeout):
                hello = await self.hello
                await self.inactive
        except TimeoutError:
            raise ProfileError(f"{req.target}: no INACTIVE within {req.start_timeout} s") from None
        if self.error is not None:
            raise ProfileError(f"{req.target} failed to initialize: {self.error}")
        return hello

    async def wire(self, hello: Hello) -> None:
        """Connect every OutPort to our sink and start feeding every InPort."""
        assert self.channel is not None
        sink = f"unix://{self.server.addresses['unix']}"
        for port in hello.ports["out"]:
            conn = Conn(f"profile-{port}", port, sink, port, {})
            await self.channel.command(Connect(conn))
        to = f"unix://{hello.data['unix']}"
        for port in hello.ports["in"]:
            source, self.inputs[port] = make_source(port, self.req.inputs.get(port, ""))
            feeder = Connection(f"profile-{port}", to, port, f"profile.{port}", ConnectorPolicy())
            feeder.start()
            self.feeders[port] = feeder
            self.feeds.append(asyncio.create_task(_feed(feeder, source, self.req.input_rate)))

    async def measure(self) -> tuple[list[float], list[int]]:
        """Activate, then sample CPU % and RSS for `seconds`; ([cpu], [rss])."""
        assert self.channel is not None
        assert self.proc is not None
        meter = ProcessTreeMeter(self.proc.pid)
        meter.measure()  # psutil's cpu_percent measures from the previous call
        await self.channel.command(Activate())
        self.recording = True
        loop = asyncio.get_running_loop()
        cpu: list[float] = []
        rss: list[int] = []
        end = loop.time() + self.req.seconds
        while (left := end - loop.time()) > 0:
            await asyncio.sleep(min(self.req.sample_interval, left))
            c, r = meter.measure()
            cpu.append(c)
            rss.append(r)
        await asyncio.sleep(HEARTBEAT * 0.2)  # a heartbeat landing just at the end still counts
        self.recording = False
        if self.error is not None:
            raise ProfileError(f"{self.req.target} went to ERROR while measured: {self.error}")
        return cpu, rss

    async def stop(self) -> None:
        """Stop feeding, tell the host to exit (kill it after 5 s), clean up."""
        for task in self.feeds:
            task.cancel()
        await asyncio.gather(*self.feeds, return_exceptions=True)
        for feeder in self.feeders.values():
            await feeder.close(linger=0.1)
        if self.channel is not None:
            with contextlib.suppress(SdrpeerError):
                await self.channel.command(Exit(2.0), wait=4.0)
        if self.proc is not None:
            try:
                async with asyncio.timeout(5.0):
                    await self.proc.wait()
            except TimeoutError:
                self.proc.kill()
                await self.proc.wait()
        if self.channel is not None:
            await self.channel.close()
        await self.server.close()
        shutil.rmtree(self.run_dir, ignore_errors=True)

    def _report(self, report: Report) -> None:
        match report:
            case Hello() if not self.hello.done():
                self.hello.set_result(report)
            case State():
                self._state(report)
            case Heartbeat():
                self._beat(report)
            case _:
                pass

    def _state(self, msg: State) -> None:
        if msg.state == LifecycleState.ERROR:
            self.error = str(msg.error)
        if (
            msg.state in (LifecycleState.INACTIVE, LifecycleState.ERROR)
            and not self.inactive.done()
        ):
            self.inactive.set_result(None)

    def _beat(self, msg: Heartbeat) -> None:
        if self.recording:
            sent = {name: c.bytes_out for name, c in self.feeders.items()}
            self.beats.append((msg.ts, msg.ports, sent))

    def _closed(self, reason: str | None) -> None:
        for fut in (self.hello, self.inactive):
            if not fut.done():
                fut.set_exception(ProfileError(f"host closed its control channel ({reason})"))


async def run_profile(req: ProfileRequest) -> dict[str, Any]:
    """Run the component in a host, measure it for `req.seconds`, return the profile map."""
    if req.seconds < 1.0:
        raise ProfileError(f"--seconds {req.seconds}: at least 1 s (heartbeats come every 0.5 s)")
    session = _Session(req)
    try:
        hello = await session.start()
        await session.wire(hello)
        cpu, rss = await session.measure()
        ports = port_rates(
            session.beats,
            {
                **dict.fromkeys(hello.ports["out"], "out"),
                **dict.fromkeys(hello.ports["in"], "in"),
            },
        )
        assert session.channel is not None
        with contextlib.suppress(SdrpeerError):
            await session.channel.command(Deactivate())
    except ProfileError as exc:
        raise ProfileError(f"{exc}; host log:\n{session.log_tail()}") from None
    finally:
        await session.stop()
    return {
        "component": hello.component,
        "target": req.target,
        "params": hello.params,
        "seconds": req.seconds,
        "cpu": {
            "mean_pct": round(sum(cpu) / len(cpu), 2),
            "peak_pct": round(max(cpu), 2),
            "samples": len(cpu),
        },
        "memory": {
            "peak_rss": max(rss),
            "peak_rss_human": format_size(max(rss)),
            "mean_rss": sum(rss) // len(rss),
        },
        "ports": ports,
        "inputs": session.inputs,
        "input_rate": req.input_rate,
        "measured_at": dt.datetime.now(dt.UTC).isoformat(timespec="seconds"),
        "host": host_info(),
    }


def write_profile(profile: Mapping[str, Any], out: Path | None) -> str:
    """The profile as YAML; also written to `out` (parents created) when given."""
    text = yaml.safe_dump(dict(profile), sort_keys=False, default_flow_style=False)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(text)
    return text
