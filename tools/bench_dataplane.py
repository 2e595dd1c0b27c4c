"""Data-plane benchmark: sdrpeer streams against pyzmq and plain sockets, between two processes.

Usage: python tools/bench_dataplane.py [--json out.json] [--quick] [--reps N]

How it works: every measurement spawns its peer as a subprocess running this file with
``--peer ROLE`` (stdout carries one JSON line with its address, then one with its result), so
sender and receiver are separate processes on this machine, as two component hosts would be.
- throughput: from the sender's first send (connection set up) to the receiver's last frame,
  both read from CLOCK_MONOTONIC (`time.perf_counter`, one clock for both processes); 100-byte
  frames in frames/s, 1 MB frames in MB/s (10^6 bytes);
- round trip: the sender times each 100-byte ping until its pong arrives; p50 and p99 in µs.
  `asyncio_raw` (a bare asyncio Protocol echo, no framing at all) is the floor of any design
  on asyncio's event loop, shown for scale.
Contenders: sdrpeer (Connection -> DataServer; policy fifo + block, TCP or Unix socket), pyzmq
(PUSH/PULL, REQ/REP; blocking sockets), a plain length-prefixed socket loop (one sendall per
frame; the receiver parses frames out of a recv_into buffer and makes each a bytes object) and
the same loop sending frames coalesced by 256. Every cell is the median of --reps runs; the
contenders run interleaved within each rep, and a target's ratio is the median over reps of the
ratio measured within one rep (the load of this shared machine shifts between reps).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import socket
import statistics
import struct
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from typing import Any

import zmq

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.testing import make_policy

SMALL, BIG = 100, 1_000_000
LEN = struct.Struct(">I")
# (target name, contender, baseline, minimum ratio contender/baseline)
THROUGHPUT_TARGETS = [
    ("100 B >= 1.0x pyzmq", ("small", "sdrpeer_tcp"), ("small", "zmq"), 1.0),
    ("1 MB TCP >= 0.8x plain TCP", ("big", "sdrpeer_tcp"), ("big", "plain_tcp"), 0.8),
    ("1 MB same-robot >= 1.5x plain TCP", ("big", "sdrpeer_unix"), ("big", "plain_tcp"), 1.5),
]
RTT_TARGET = 1.3  # sdrpeer p50 <= 1.3x plain socket p50


# ---- peers (run in the subprocess) --------------------------------------------------------


def _emit(obj: object) -> None:
    print(json.dumps(obj), flush=True)


class _CountingPort:
    def __init__(self, n: int, done: asyncio.Future[None]) -> None:
        self.n, self.count, self.t1, self.done = n, 0, 0.0, done

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        self.count += 1
        if self.count == self.n:
            self.t1 = time.perf_counter()
            self.done.set_result(None)

    def refuse(self) -> None:
        raise RuntimeError("refused a frame")


async def _peer_sdr_sink(n: int, unix: str) -> None:
    done = asyncio.get_running_loop().create_future()
    port = _CountingPort(n, done)
    server = DataServer(lambda name: port, unix_path=unix)
    await server.start()
    _emit(server.addresses)
    await done
    _emit({"end": port.t1})
    await server.close()


async def _peer_sdr_echo(reply_to: str) -> None:
    back = Connection("pong", reply_to, "pong", "echo.out", make_policy("fifo", 1024, "block"))

    class Echo:
        def deliver(self, value: Any, seq: int, conn: str) -> None:
            back.offer(value)

        def refuse(self) -> None:
            raise RuntimeError("refused a frame")

    echo = Echo()
    server = DataServer(lambda name: echo)
    await server.start()
    back.start()
    await back.wait_connected()
    _emit(server.addresses)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until parent exits
    await back.close()
    await server.close()


async def _peer_asyncio_echo() -> None:
    class Echo(asyncio.Protocol):
        def connection_made(self, transport: asyncio.BaseTransport) -> None:
            assert isinstance(transport, asyncio.Transport)
            self.transport = transport

        def data_received(self, data: bytes) -> None:
            self.transport.write(data)

    server = await asyncio.get_running_loop().create_server(Echo, "127.0.0.1", 0)
    _emit({"tcp": f"127.0.0.1:{server.sockets[0].getsockname()[1]}"})
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)
    server.close()


def _peer_plain_sink(n: int) -> None:
    listener = socket.create_server(("127.0.0.1", 0))
    _emit({"tcp": f"127.0.0.1:{listener.getsockname()[1]}"})
    sock, _ = listener.accept()
    buf = bytearray(8 * 1024 * 1024)
    view = memoryview(buf)
    start = end = count = 0
    while count < n:
        got = sock.recv_into(view[end:])
        if not got:
            raise ConnectionError("sender closed early")
        end += got
        while end - start >= 4:
            size = LEN.unpack_from(buf, start)[0]
            if end - start - 4 < size:
                break
            frame = bytes(view[start + 4 : start + 4 + size])  # the value handed on
            start += 4 + size
            count += 1
        if start == end:
            start = end = 0
        elif len(buf) - end < 2 * 1024 * 1024:
            buf[: end - start] = buf[start:end]
            start, end = 0, end - start
    del frame
    _emit({"end": time.perf_counter()})


def _peer_plain_echo() -> None:
    listener = socket.create_server(("127.0.0.1", 0))
    _emit({"tcp": f"127.0.0.1:{listener.getsockname()[1]}"})
    sock, _ = listener.accept()
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    while True:
        head = _recv_exact(sock, 4)
        if not head:
            return
        sock.sendall(head + _recv_exact(sock, LEN.unpack(head)[0]))


def _recv_exact(sock: socket.socket, size: int) -> bytes:
    parts, got = [], 0
    while got < size:
        part = sock.recv(size - got)
        if not part:
            return b""
        parts.append(part)
        got += len(part)
    return b"".join(parts)


def _peer_zmq(role: str, n: int) -> None:
    ctx = zmq.Context()
    sock = ctx.socket(zmq.PULL if role == "zmq-pull" else zmq.REP)
    port = sock.bind_to_random_port("tcp://127.0.0.1")
    _emit({"tcp": f"127.0.0.1:{port}"})
    if role == "zmq-rep":
        while (msg := sock.recv()) != b"":
            sock.send(msg)
        sock.send(b"")
    else:
        for _ in range(n):
            sock.recv()
        _emit({"end": time.perf_counter()})
    sock.close(linger=0)
    ctx.term()


def run_peer(role: str, n: int, arg: str) -> None:
    """The subprocess side of one measurement (BENCH_PROFILE=path: cProfile it into path)."""
    profile = os.environ.get("BENCH_PROFILE")
    if profile:
        import cProfile  # noqa: PLC0415 - only when profiling

        with cProfile.Profile() as prof:
            _run_peer(role, n, arg)
        prof.dump_stats(profile)
    else:
        _run_peer(role, n, arg)


def _run_peer(role: str, n: int, arg: str) -> None:
    if role == "sdr-sink":
        asyncio.run(_peer_sdr_sink(n, arg))
    elif role == "sdr-echo":
        asyncio.run(_peer_sdr_echo(arg))
    elif role == "plain-sink":
        _peer_plain_sink(n)
    elif role == "plain-echo":
        _peer_plain_echo()
    elif role == "asyncio-echo":
        asyncio.run(_peer_asyncio_echo())
    else:
        _peer_zmq(role, n)


# ---- senders (the parent process) ---------------------------------------------------------


class Peer:
    """A peer subprocess: its advertised addresses, then its result."""

    def __init__(self, role: str, n: int = 0, arg: str = "") -> None:
        cmd = [sys.executable, os.path.abspath(__file__), "--peer", role, str(n), arg]
        self.proc = subprocess.Popen(cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
        self.addresses: dict[str, str] = self._line()

    def _line(self) -> dict[str, Any]:
        assert self.proc.stdout is not None
        line = self.proc.stdout.readline()
        if not line:
            raise RuntimeError(f"peer {self.proc.args!r} died (exit {self.proc.wait()})")
        return json.loads(line)  # type: ignore[no-any-return]

    def tcp(self) -> tuple[str, int]:
        host, port = self.addresses["tcp"].rsplit(":", 1)
        return host, int(port)

    def finish(self) -> dict[str, Any]:
        result = self._line()
        self.stop()
        return result

    def stop(self) -> None:
        assert self.proc.stdin is not None
        self.proc.stdin.close()
        self.proc.wait(timeout=30)


def payload(size: int) -> bytes:
    """A value of `size` bytes."""
    return os.urandom(size)


async def _sdr_send(to: str, n: int, size: int) -> float:
    buffer = 4096 if size <= 1024 else 4
    conn = Connection("bench", to, "sink", "bench.out", make_policy("fifo", buffer, "block"))
    conn.start()
    async with asyncio.timeout(10):
        await conn.wait_connected()
    value, offer, drain = payload(size), conn.offer, conn.drain
    start = time.perf_counter()
    for _ in range(n):
        if not offer(value):
            await drain()
            offer(value)
    await conn.close(linger=60)
    return start


def sdr_throughput(kind: str, n: int, size: int) -> float:
    """Seconds the sdrpeer receiver took for n frames of `size` bytes."""
    with tempfile.TemporaryDirectory() as tmp:
        peer = Peer("sdr-sink", n, os.path.join(tmp, "rx.sock"))
        start = asyncio.run(_sdr_send(f"{kind}://{peer.addresses[kind]}", n, size))
        return float(peer.finish()["end"]) - start


def plain_throughput(n: int, size: int, batch: int = 1) -> float:
    """Seconds the plain socket receiver took; `batch` frames per sendall."""
    peer = Peer("plain-sink", n)
    sock = socket.create_connection(peer.tcp())
    frame = LEN.pack(size) + payload(size)
    chunk = frame * batch
    start = time.perf_counter()
    for _ in range(n // batch):
        sock.sendall(chunk)
    for _ in range(n % batch):
        sock.sendall(frame)
    seconds = float(peer.finish()["end"]) - start
    sock.close()
    return seconds


def zmq_throughput(n: int, size: int) -> float:
    """Seconds the pyzmq PULL receiver took."""
    peer = Peer("zmq-pull", n)
    ctx = zmq.Context()
    sock = ctx.socket(zmq.PUSH)
    sock.connect(f"tcp://{peer.addresses['tcp']}")
    value = payload(size)
    start = time.perf_counter()
    for _ in range(n):
        sock.send(value)
    seconds = float(peer.finish()["end"]) - start
    sock.close(linger=0)
    ctx.term()
    return seconds


async def _sdr_pings(m: int) -> list[float]:
    loop = asyncio.get_running_loop()
    waiter: list[asyncio.Future[None]] = []

    class Pong:
        def deliver(self, value: Any, seq: int, conn: str) -> None:
            waiter.pop().set_result(None)

        def refuse(self) -> None:
            raise RuntimeError("refused a frame")

    pong = Pong()
    server = DataServer(lambda name: pong)
    await server.start()
    peer = await asyncio.to_thread(Peer, "sdr-echo", 0, f"tcp://{server.addresses['tcp']}")
    conn = Connection("ping", f"tcp://{peer.addresses['tcp']}", "ping", "b.out", make_policy())
    conn.start()
    async with asyncio.timeout(10):
        await conn.wait_connected()
    value, times = payload(SMALL), []
    for _ in range(m):
        fut = loop.create_future()
        waiter.append(fut)
        t0 = time.perf_counter()
        conn.offer(value)
        await fut
        times.append(time.perf_counter() - t0)
    await conn.close()
    peer.stop()
    await server.close()
    return times


async def _asyncio_pings(m: int) -> list[float]:
    """Round trips of a bare asyncio Protocol ping-pong: the floor under any asyncio design."""
    loop = asyncio.get_running_loop()
    waiter: list[asyncio.Future[None]] = []

    class Ping(asyncio.Protocol):
        def data_received(self, data: bytes) -> None:
            waiter.pop().set_result(None)

    peer = await asyncio.to_thread(Peer, "asyncio-echo")
    transport, _ = await loop.create_connection(Ping, *peer.tcp())
    frame, times = LEN.pack(SMALL) + payload(SMALL), []
    for _ in range(m):
        fut = loop.create_future()
        waiter.append(fut)
        t0 = time.perf_counter()
        transport.write(frame)
        await fut
        times.append(time.perf_counter() - t0)
    transport.close()
    peer.stop()
    return times


def plain_pings(m: int) -> list[float]:
    """Round trips of a blocking socket ping-pong."""
    peer = Peer("plain-echo")
    sock = socket.create_connection(peer.tcp())
    sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
    frame, times = LEN.pack(SMALL) + payload(SMALL), []
    for _ in range(m):
        t0 = time.perf_counter()
        sock.sendall(frame)
        _recv_exact(sock, len(frame))
        times.append(time.perf_counter() - t0)
    sock.close()
    peer.stop()
    return times


def zmq_pings(m: int) -> list[float]:
    """Round trips of pyzmq REQ/REP."""
    peer = Peer("zmq-rep")
    ctx = zmq.Context()
    sock = ctx.socket(zmq.REQ)
    sock.connect(f"tcp://{peer.addresses['tcp']}")
    value, times = payload(SMALL), []
    for _ in range(m):
        t0 = time.perf_counter()
        sock.send(value)
        sock.recv()
        times.append(time.perf_counter() - t0)
    sock.send(b"")
    sock.recv()
    sock.close(linger=0)
    ctx.term()
    peer.stop()
    return times


# ---- the report ---------------------------------------------------------------------------


def measure(
    quick: bool, reps: int, log: Callable[[str], None], only: str = "small,big,rtt"
) -> dict[str, Any]:
    """Every figure (or the sections in `only`), medians of `reps` runs."""
    n_small, n_big, m = (20_000, 20, 300) if quick else (300_000, 500, 5000)
    small: dict[str, Callable[[], float]] = {
        "sdrpeer_tcp": lambda: sdr_throughput("tcp", n_small, SMALL),
        "sdrpeer_unix": lambda: sdr_throughput("unix", n_small, SMALL),
        "zmq": lambda: zmq_throughput(n_small, SMALL),
        "plain_tcp": lambda: plain_throughput(n_small, SMALL),
        "plain_tcp_coalesced": lambda: plain_throughput(n_small, SMALL, batch=256),
    }
    big: dict[str, Callable[[], float]] = {
        "sdrpeer_tcp": lambda: sdr_throughput("tcp", n_big, BIG),
        "sdrpeer_unix": lambda: sdr_throughput("unix", n_big, BIG),
        "plain_tcp": lambda: plain_throughput(n_big, BIG),
        "zmq": lambda: zmq_throughput(n_big, BIG),
    }
    pings: dict[str, Callable[[], list[float]]] = {
        "sdrpeer_tcp": lambda: asyncio.run(_sdr_pings(m)),
        "plain_tcp": lambda: plain_pings(m),
        "zmq": lambda: zmq_pings(m),
        "asyncio_raw": lambda: asyncio.run(_asyncio_pings(m)),
    }
    out: dict[str, Any] = {"quick": quick, "reps": reps, "small": {}, "big": {}, "rtt": {}}
    runs: dict[tuple[str, str], list[float]] = {}
    for rep in range(reps):  # interleaved, so slow phases of the machine hit every contender
        log(f"rep {rep + 1}/{reps}")
        if "small" not in only:
            small = {}
        if "big" not in only:
            big = {}
        if "rtt" not in only:
            pings = {}
        for name, run in small.items():
            runs.setdefault(("small", name), []).append(n_small / run())
        for name, run in big.items():
            runs.setdefault(("big", name), []).append(n_big * BIG / 1e6 / run())
        for name, ping in pings.items():
            times = sorted(ping()[m // 10 :])  # the first tenth warms up
            runs.setdefault(("p50", name), []).append(times[len(times) // 2] * 1e6)
            runs.setdefault(("p99", name), []).append(times[int(len(times) * 0.99)] * 1e6)
    for (section, name), values in runs.items():
        if section in ("small", "big"):
            out[section][name] = {"median": statistics.median(values), "runs": values}
        else:
            cell = out["rtt"].setdefault(name, {})
            cell[f"{section}_us"] = statistics.median(values)
            cell[f"{section}_runs"] = values

    def paired(a: tuple[str, str], b: tuple[str, str]) -> float:
        """Median over reps of the ratio within each rep (the machine's load shifts cancel)."""
        return statistics.median(x / y for x, y in zip(runs[a], runs[b], strict=True))

    targets = []
    for label, (sec, name), (bsec, base), minimum in THROUGHPUT_TARGETS:
        if sec in only:
            ratio = paired((sec, name), (bsec, base))
            targets.append({"target": label, "ratio": ratio, "met": ratio >= minimum})
    if "rtt" in only:
        ratio = paired(("p50", "sdrpeer_tcp"), ("p50", "plain_tcp"))
        met = ratio <= RTT_TARGET
        targets.append({"target": "RTT p50 <= 1.3x plain", "ratio": ratio, "met": met})
    out["targets"] = targets
    return out


def render(out: dict[str, Any]) -> str:
    """The figures as a text table."""
    lines = [f"100-byte frames, frames/s (median of {out['reps']})"]
    lines += [f"  {k:<22} {v['median']:>12,.0f}" for k, v in out["small"].items()]
    lines.append("1 MB frames, MB/s")
    lines += [f"  {k:<22} {v['median']:>12,.0f}" for k, v in out["big"].items()]
    lines.append("100-byte round trip, µs        p50      p99")
    lines += [f"  {k:<22} {v['p50_us']:>9.1f} {v['p99_us']:>8.1f}" for k, v in out["rtt"].items()]
    lines.append("Targets (median of per-rep ratios)")
    for t in out["targets"]:
        lines.append(f"  {t['target']:<36} {t['ratio']:>6.2f}x  {'met' if t['met'] else 'MISSED'}")
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark (or, with --peer, one peer of it)."""
    if argv is None:
        argv = sys.argv[1:]
    if argv[:1] == ["--peer"]:
        run_peer(argv[1], int(argv[2]), argv[3] if len(argv) > 3 else "")
        return 0
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="PATH", help="also write every figure to this file")
    parser.add_argument("--quick", action="store_true", help="small counts, one rep: a smoke test")
    parser.add_argument("--reps", type=int, help="runs per cell (default 5, quick 1)")
    parser.add_argument("--only", default="small,big,rtt", help="sections: small,big,rtt")
    args = parser.parse_args(argv)
    reps = args.reps or (1 if args.quick else 5)
    out = measure(
        args.quick, reps, lambda text: print(text, file=sys.stderr, flush=True), args.only
    )
    print(render(out))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
