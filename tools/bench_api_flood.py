#!/usr/bin/env python3
"""Does an agent's API answer its own robot under a connection flood? Latency of /v1/members.

Starts one real agent (`sdrpeer.lab.up`, one robot), then in two phases calls its
`GET /v1/members` every `--interval` s for `--seconds` s, each call a fresh connection as the
command line makes it (one HTTP/1.1 exchange, `Connection: close`, as `sdrpeer.client`; 5 s
timeout), and records its latency, the TCP connect's part of it, and the status:
- baseline: nobody else connects;
- flood: a child process holds `--connections` TCP connections to the API (default 2,000),
  every `--dribble-every`-th (default 5th) sending a request head one byte every
  `--byte-interval` s (default 1 s, a slowloris), the others sending nothing; a connection the
  agent closes is opened again at once (`--no-reopen`: left closed), so the flood keeps trying to
  hold them all. The calls start once every flood connection has been opened once.
Prints a table (calls, failures, p50/p95/max latency, calls over 1 s) per phase, the flood's own
counts, the agent's `api_connections` counters (`GET /v1/agent`) and the target line (issue 30:
every call under the flood answered 200 within 1 s); `--json FILE` writes the figures. The
agent is always stopped, also on error or Ctrl-C.

    .venv/bin/python tools/bench_api_flood.py --json /tmp/api_flood.json

`Flood` is also what tests/test_api_server.py floods a server with.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing
import resource
import socket
import statistics
import sys
import tempfile
import time
from collections.abc import Callable
from multiprocessing.connection import Connection
from pathlib import Path
from typing import Any

import psutil

HEAD_START = b"GET /v1/members HTTP/1.1\r\nHost: robot\r\nX-Slow: "
"""What a dribbling connection sends at once; then one byte of its header value at a time."""
TARGET_S = 1.0
CALL_TIMEOUT = 5.0
READY_WAIT = 120.0
"""Seconds the flood may take to open every connection once."""


def raise_fd_limit(wanted: int) -> int:
    """Raise this process's soft descriptor limit to `wanted` (at most the hard limit); the
    limit now."""
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft < wanted:
        soft = wanted if hard == resource.RLIM_INFINITY else min(wanted, hard)
        resource.setrlimit(resource.RLIMIT_NOFILE, (soft, hard))
    return soft


class Flood:
    """`connections` TCP connections held to host:port; every `dribble_every`-th (0: none)
    dribbles a request head, one byte per `byte_interval` s; the others send nothing. A
    connection the server closes is opened again while `reopen`, for at most `max_opens` opens in
    all (each slot's loop is bounded by it and by `stop`). `source`: the local address to
    connect from (another loopback address stands for another host). `opening`: at most this
    many connects under way at once (None: all at once, a burst)."""

    def __init__(
        self,
        host: str,
        port: int,
        connections: int,
        *,
        dribble_every: int = 5,
        byte_interval: float = 1.0,
        reopen: bool = True,
        max_opens: int = 1_000_000,
        source: str | None = None,
        opening: int | None = None,
    ) -> None:
        self.host, self.port, self.connections, self.source = host, port, connections, source
        self._opening = None if opening is None else asyncio.Semaphore(opening)
        self.dribble_every, self.byte_interval = dribble_every, byte_interval
        self.reopen, self.max_opens = reopen, max_opens
        self.counts = {"opened": 0, "open_failed": 0, "closed_by_server": 0, "bytes_dribbled": 0}
        self.held = 0
        """Connections open from the flood's side now."""
        self.all_opened = asyncio.Event()
        """Set once `connections` connections have been opened (each at least once)."""

    async def run(self, stop: asyncio.Event) -> None:
        """Hold the connections until `stop` is set."""
        async with asyncio.TaskGroup() as group:
            for i in range(self.connections):
                dribbles = self.dribble_every > 0 and i % self.dribble_every == 0
                group.create_task(self._slot(dribbles, stop))

    async def _slot(self, dribbles: bool, stop: asyncio.Event) -> None:
        while not stop.is_set() and self.counts["opened"] < self.max_opens:
            try:
                reader, writer = await self._open()
            except OSError:
                self.counts["open_failed"] += 1
                await _wait(stop, 0.1)
                continue
            self.counts["opened"] += 1
            self.held += 1
            if self.counts["opened"] >= self.connections:
                self.all_opened.set()
            try:
                if dribbles:
                    closed = await self._dribble(reader, writer, stop)
                else:
                    closed = await _until_closed(reader, stop)
            finally:
                self.held -= 1
                writer.close()
            if closed:
                self.counts["closed_by_server"] += 1
            if not self.reopen:
                await stop.wait()

    async def _open(self) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
        local = None if self.source is None else (self.source, 0)
        if self._opening is None:
            return await asyncio.open_connection(self.host, self.port, local_addr=local)
        async with self._opening:
            return await asyncio.open_connection(self.host, self.port, local_addr=local)

    async def _dribble(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, stop: asyncio.Event
    ) -> bool:
        try:
            writer.write(HEAD_START)
            while not stop.is_set():
                try:
                    async with asyncio.timeout(self.byte_interval):
                        if await reader.read(1) == b"":
                            return True  # closed by the server
                except TimeoutError:
                    writer.write(b"a")
                    self.counts["bytes_dribbled"] += 1
                    await writer.drain()
        except OSError:
            return True
        return False


async def _until_closed(reader: asyncio.StreamReader, stop: asyncio.Event) -> bool:
    """Whether the server closed the connection before `stop` was set."""
    read = asyncio.ensure_future(reader.read())
    stopped = asyncio.ensure_future(stop.wait())
    done, pending = await asyncio.wait({read, stopped}, return_when=asyncio.FIRST_COMPLETED)
    for task in pending:
        task.cancel()
    if read not in done:
        return False
    return read.exception() is not None or read.result() == b""


async def _wait(stop: asyncio.Event, seconds: float) -> None:
    try:
        async with asyncio.timeout(seconds):
            await stop.wait()
    except TimeoutError:
        pass


# ------------------------------------------------------------------ the flood's own process
def flood_process(
    host: str, port: int, settings: dict[str, Any], conn: Connection, max_s: float
) -> None:
    """A child process's flood: says `ready` (with counts) once every connection was opened,
    holds them until the parent says `stop` (or `max_s` s), then sends its counts."""
    raise_fd_limit(settings["connections"] + 256)
    asyncio.run(_flood_main(host, port, settings, conn, max_s))


async def _flood_main(
    host: str, port: int, settings: dict[str, Any], conn: Connection, max_s: float
) -> None:
    flood = Flood(host, port, **settings)
    stop = asyncio.Event()
    task = asyncio.create_task(flood.run(stop))
    loop = asyncio.get_running_loop()
    start = loop.time()
    try:
        async with asyncio.timeout(READY_WAIT):
            await flood.all_opened.wait()
    except TimeoutError:
        pass  # said below: the counts show how many were opened
    conn.send(("ready", round(loop.time() - start, 3), dict(flood.counts), flood.held))
    await asyncio.to_thread(conn.poll, max(0.0, start + max_s - loop.time()))  # "stop"
    held = flood.held
    stop.set()
    await task
    conn.send(("done", dict(flood.counts), held))


# ------------------------------------------------------------------------- the robot's caller
def probe(api: str, seconds: float, interval: float) -> list[dict[str, Any]]:
    """Call GET /v1/members every `interval` s for `seconds` s: each call's latency (and of it,
    the TCP connect), and its outcome."""
    host, port = api.removeprefix("http://").rsplit(":", 1)
    calls = []
    start = time.monotonic()
    for i in range(max(1, round(seconds / interval))):
        delay = start + i * interval - time.monotonic()
        if delay > 0:
            time.sleep(delay)
        t0 = time.perf_counter()
        connect_s = None
        try:
            with socket.create_connection((host, int(port)), CALL_TIMEOUT) as sock:
                connect_s = time.perf_counter() - t0
                outcome = _members(sock, f"{host}:{port}")
        except OSError as exc:
            outcome = f"{type(exc).__name__}: {exc}"
        calls.append(
            {
                "latency_s": round(time.perf_counter() - t0, 4),
                "connect_s": None if connect_s is None else round(connect_s, 4),
                "outcome": outcome,
            }
        )
    return calls


def _members(sock: socket.socket, netloc: str) -> str:
    """One `GET /v1/members` on `sock` as `sdrpeer.client` makes it (HTTP/1.1, Connection:
    close, the answer read to its end): "200", or what came back instead."""
    sock.sendall(
        f"GET /v1/members HTTP/1.1\r\nHost: {netloc}\r\nConnection: close\r\n"
        "Accept: application/json\r\n\r\n".encode()
    )
    chunks = []
    while chunk := sock.recv(1 << 16):
        chunks.append(chunk)
    head, _, body = b"".join(chunks).partition(b"\r\n\r\n")
    status = head.split(b" ", 2)[1].decode() if head.startswith(b"HTTP/1.1 ") else ""
    if not status:
        return f"not HTTP: {head[:40]!r}"
    if status == "200" and not body.strip().startswith(b"["):
        return "200 but not a list"
    return status


def summary(calls: list[dict[str, Any]]) -> dict[str, Any]:
    """Counts and latency percentiles of one phase's calls."""
    lat = sorted(c["latency_s"] for c in calls)
    ok = [c for c in calls if c["outcome"] == "200"]
    failures: dict[str, int] = {}
    for c in calls:
        if c["outcome"] != "200":
            failures[c["outcome"][:80]] = failures.get(c["outcome"][:80], 0) + 1
    return {
        "calls": len(calls),
        "ok": len(ok),
        "failed": len(calls) - len(ok),
        "failures": failures,
        "connect_p95_s": _p95([c["connect_s"] for c in calls if c["connect_s"] is not None]),
        "connect_max_s": max(
            (c["connect_s"] for c in calls if c["connect_s"] is not None), default=None
        ),
        "p50_s": round(statistics.median(lat), 4),
        "p95_s": _p95(lat),
        "max_s": lat[-1],
        "over_target": sum(1 for c in calls if c["latency_s"] > TARGET_S),
    }


def measured(agent: psutil.Process, phase: Callable[[], list[dict[str, Any]]]) -> dict[str, Any]:
    """`phase`'s calls summed up, with the agent's CPU time over it (s, and % of one core) and
    its RSS at the end (MiB)."""
    cpu0, t0 = sum(agent.cpu_times()[:2]), time.monotonic()
    result = summary(phase())
    cpu = sum(agent.cpu_times()[:2]) - cpu0
    result["agent_cpu_pct_of_core"] = round(100 * cpu / (time.monotonic() - t0), 1)
    result["agent_rss_mib_at_end"] = round(agent.memory_info().rss / 2**20, 1)
    return result


def _p95(values: list[float]) -> float | None:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(0.95 * len(ordered)))] if ordered else None


def run(args: argparse.Namespace, lab_dir: Path) -> dict[str, Any]:
    """Start the agent, measure both phases, stop the agent; the JSON report."""
    from sdrpeer.client import AgentClient  # noqa: PLC0415
    from sdrpeer.lab.up import UpOptions, log_tail, start_lab  # noqa: PLC0415

    running = start_lab(UpOptions(robots=1, lab_dir=lab_dir, timeout=30.0), say=print)
    robot = running.lab.robots[0]
    api = robot.api
    assert api is not None
    host, port = api.removeprefix("http://").rsplit(":", 1)
    settings = {
        "connections": args.connections,
        "dribble_every": args.dribble_every,
        "byte_interval": args.byte_interval,
        "reopen": not args.no_reopen,
    }
    report: dict[str, Any] = {"api": robot.api, "flood": dict(settings)}
    agent = psutil.Process(running.procs[robot.name].pid)
    try:
        print(f"baseline: GET /v1/members every {args.interval:g} s for {args.seconds:g} s")
        report["baseline"] = measured(agent, lambda: probe(api, args.seconds, args.interval))
        ctx = multiprocessing.get_context("spawn")
        ours, theirs = ctx.Pipe()
        child = ctx.Process(
            target=flood_process,
            args=(host, int(port), settings, theirs, args.seconds + READY_WAIT + 60),
        )
        child.start()
        try:
            if not ours.poll(READY_WAIT + 30):
                raise RuntimeError("the flood did not report ready")
            _, ready_s, counts, held = ours.recv()
            report["flood"].update(ready_s=ready_s, at_ready=counts, held_at_ready=held)
            print(f"flood: {args.connections} connections opened in {ready_s} s; measuring")
            report["under_flood"] = measured(agent, lambda: probe(api, args.seconds, args.interval))
            ours.send("stop")
            if ours.poll(60):
                _, counts, held = ours.recv()
                report["flood"].update(at_end=counts, held_at_end=held)
        finally:
            child.join(30)
            if child.is_alive():
                child.kill()
        report["agent_api_connections"] = AgentClient(api).get("/v1/agent")["api_connections"]
    except BaseException:
        print(f"agent log tail:\n{log_tail(Path(robot.log))}", file=sys.stderr)
        raise
    finally:
        for line in running.stop():
            print(f"  {line}")
    flood = report["under_flood"]
    report["target"] = {
        "every_call_200_within_s": TARGET_S,
        "met": flood["failed"] == 0 and flood["over_target"] == 0,
    }
    return report


def table(report: dict[str, Any]) -> str:
    """The figures as a text table."""
    rows = [
        "phase        calls  ok  failed  p50 ms  p95 ms  max ms  over 1 s  connect p95/max ms"
        "  agent CPU %  RSS MiB",
    ]
    for phase in ("baseline", "under_flood"):
        s = report[phase]
        rows.append(
            f"{phase:<12} {s['calls']:>5} {s['ok']:>3} {s['failed']:>7} "
            f"{s['p50_s'] * 1000:>7.1f} {s['p95_s'] * 1000:>7.1f} {s['max_s'] * 1000:>7.1f} "
            f"{s['over_target']:>9}  {_ms(s['connect_p95_s']) + '/' + _ms(s['connect_max_s']):>18}"
            f"  {s['agent_cpu_pct_of_core']:>11.1f}  {s['agent_rss_mib_at_end']:>7.1f}"
        )
        if s["failures"]:
            rows.append(f"  failures: {s['failures']}")
    f = report["flood"]
    rows.append(
        f"flood: {f['connections']} connections (1 in {f['dribble_every']} dribbling a byte "
        f"every {f['byte_interval']:g} s, reopen {f['reopen']}), all opened once in "
        f"{f['ready_s']} s; at the end {f.get('held_at_end')} held from its side; "
        f"counts {f.get('at_end')}"
    )
    rows.append(f"agent api_connections: {report['agent_api_connections']}")
    met = "MET" if report["target"]["met"] else "NOT MET"
    rows.append(f"target (every call under the flood 200 within {TARGET_S:g} s): {met}")
    return "\n".join(rows)


def _ms(seconds: float | None) -> str:
    return "-" if seconds is None else f"{seconds * 1000:.1f}"


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--no-reopen", action="store_true", help="leave shed connections closed")
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the figures as JSON")
    parser.add_argument("--connections", type=int, default=2000, help="flood size (2000)")
    parser.add_argument("--dribble-every", type=int, default=5, help="1 in N dribbles (5)")
    parser.add_argument("--byte-interval", type=float, default=1.0, help="dribble pace, s (1)")
    parser.add_argument("--seconds", type=float, default=20.0, help="each phase's length (20)")
    parser.add_argument("--interval", type=float, default=0.2, help="between two calls, s (0.2)")
    args = parser.parse_args(argv)
    if args.connections < 1 or args.seconds <= 0 or args.interval <= 0:
        parser.error("need --connections >= 1, --seconds > 0, --interval > 0")
    with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-flood-") as tmp:
        try:
            report = run(args, Path(tmp))
        except KeyboardInterrupt:
            return 130
    if args.json is not None:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
    print(f"\n{table(report)}" + (f"\nwrote {args.json}" if args.json else ""))
    return 0


if __name__ == "__main__":
    sys.exit(main())
