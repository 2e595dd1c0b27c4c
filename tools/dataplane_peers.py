"""The peer processes of the data-plane benchmark (tools/bench_dataplane.py), one role each.

Usage (by the benchmark): python tools/dataplane_peers.py ROLE N ARG

How it works: `Peer` starts this file as a subprocess in one role; the peer prints one JSON line
with the addresses it listens on, then (sinks) one with the CLOCK_MONOTONIC time its last frame
arrived (`time.perf_counter`, the same clock in both processes), or (echoes) answers every ping
until its stdin closes. Roles: sdr-sink (DataServer counting N frames), sdr-inport (DataServer
into the SDK's InPort, a consumer task taking every frame as a component would, so the stream
is acknowledged and the sender keeps its window), sdr-echo (DataServer
whose frames go back through a Connection to ARG), svc-provider (a DataServer providing a
service whose `echo` method returns its argument: sdrpeer.sdk.services), asyncio-echo (a bare
asyncio Protocol), plain-sink / plain-echo (blocking sockets, 4-byte length prefix per frame:
the sink parses frames out of a recv_into buffer and makes each a bytes object), zmq-pull /
zmq-rep (pyzmq), zmq-pull-typed (each frame a msgpack array made back into the Pose
`typed_pose` gives: a typed stream done by hand with pyzmq).
BENCH_PROFILE=path runs the role under cProfile and writes its stats there.
"""

from __future__ import annotations

import asyncio
import json
import os
import socket
import struct
import subprocess
import sys
import time
from typing import Any

import msgpack
import zmq

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.testing import make_policy
from sdrpeer.keys.datakeys import ENV as DATA_KEYS_ENV
from sdrpeer.keys.datakeys import keys_from_env, keys_to_env

LEN = struct.Struct(">I")
"""The plain socket loop's frame header: the payload's length."""
SERVICE = "bench/Echo"
"""The interface the svc-provider role provides (one method, `echo`)."""


def payload(size: int) -> bytes:
    """A value of `size` bytes."""
    return os.urandom(size)


def typed_pose() -> Any:
    """A Pose (sdrpeer.sdk.robot_types) whose msgpack form is 100 bytes, like `payload(100)`."""
    from sdrpeer.sdk import Pose  # noqa: PLC0415 - only the typed rows need the SDK

    return Pose(1_700_000_000.125, "base_link_front_camera_opt", 1.5, 2.5, 0.1, 0.0, 0.0, 0.4, 0.9)


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


async def _peer_sdr_inport(n: int, unix: str, port_type: Any = None) -> None:
    """An InPort (typed: it decodes every value it gives out) and a consumer taking all."""
    from sdrpeer.sdk.inport import InPortRuntime  # noqa: PLC0415 - only this role needs the SDK
    from sdrpeer.sdk.policy import ConnectorPolicy  # noqa: PLC0415

    policy = ConnectorPolicy("fifo", 1 << 20, "block")
    port = InPortRuntime("sink", policy, port_type=port_type)
    keys = keys_from_env(os.environ.get(DATA_KEYS_ENV))  # given: authenticated, encrypted TCP
    auth = DataAuth(keys) if keys else None
    server = DataServer(lambda name: port, unix_path=unix, auth=auth)
    await server.start()
    _emit(server.addresses)
    cpu = time.process_time()  # idle until the sender connects: this counts the receiving
    count = 0
    while count < n:
        await port.get()
        count += 1
        while port.qsize():
            port.get_nowait()
            count += 1
    _emit({"end": time.perf_counter(), "cpu": time.process_time() - cpu})
    await asyncio.sleep(0.05)  # the last acknowledgements go out
    await server.close()


async def _peer_sdr_consumer(unix: str) -> None:
    """An InPort with the SDK's default policy (all, 8, overwrite) and a consumer that takes
    one frame per event-loop turn (what an OnInput component does); once nothing has arrived
    for 0.5 s, it says how many frames it took and what its InPort counted."""
    from sdrpeer.sdk.inport import InPortRuntime  # noqa: PLC0415 - only this role needs the SDK

    port = InPortRuntime("sink")
    server = DataServer(lambda name: port, unix_path=unix)
    await server.start()
    _emit(server.addresses)
    taken = 0
    while True:
        try:
            async with asyncio.timeout(0.5 if taken else 30):
                await port.get()
        except TimeoutError:
            break
        taken += 1
        await asyncio.sleep(0)
    _emit({"taken": taken, **port.counters()})
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


async def _peer_svc_provider() -> None:
    """A provided service (the SDK's provider runtime, ACTIVE) whose `echo` returns its argument,
    behind a DataServer: what a provider host serves a service binding with."""
    from sdrpeer.sdk import Interface, ServiceProviderRuntime  # noqa: PLC0415 - this role only

    def echo(value: Any) -> Any:
        return value

    port = ServiceProviderRuntime("svc", Interface.of(SERVICE, "echo"), {"echo": echo})
    port.serving = True
    server = DataServer(lambda name: None, resolve_service=lambda name: port)
    await server.start()
    _emit(server.addresses)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until parent exits
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
        head = recv_exact(sock, 4)
        if not head:
            return
        sock.sendall(head + recv_exact(sock, LEN.unpack(head)[0]))


def recv_exact(sock: socket.socket, size: int) -> bytes:
    """Exactly `size` bytes from a blocking socket (b"" if it closed first)."""
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
    sock = ctx.socket(zmq.REP if role == "zmq-rep" else zmq.PULL)
    port = sock.bind_to_random_port("tcp://127.0.0.1")
    _emit({"tcp": f"127.0.0.1:{port}"})
    if role == "zmq-rep":
        while (msg := sock.recv()) != b"":
            sock.send(msg)
        sock.send(b"")
    elif role == "zmq-pull-typed":  # the same Pose, msgpack arrays, made back into Poses
        make = type(typed_pose())
        unpackb = msgpack.unpackb
        for _ in range(n):
            make(*unpackb(sock.recv()))
        _emit({"end": time.perf_counter()})
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
    elif role == "sdr-inport":
        asyncio.run(_peer_sdr_inport(n, arg))
    elif role == "sdr-inport-typed":
        asyncio.run(_peer_sdr_inport(n, arg, type(typed_pose())))
    elif role == "sdr-consumer":
        asyncio.run(_peer_sdr_consumer(arg))
    elif role == "sdr-echo":
        asyncio.run(_peer_sdr_echo(arg))
    elif role == "plain-sink":
        _peer_plain_sink(n)
    elif role == "plain-echo":
        _peer_plain_echo()
    elif role == "asyncio-echo":
        asyncio.run(_peer_asyncio_echo())
    elif role == "svc-provider":
        asyncio.run(_peer_svc_provider())
    else:
        _peer_zmq(role, n)


class Peer:
    """A peer subprocess: its advertised addresses, then its result."""

    def __init__(
        self, role: str, n: int = 0, arg: str = "", keys: list[bytes] | None = None
    ) -> None:
        cmd = [sys.executable, os.path.abspath(__file__), role, str(n), arg]
        env = dict(os.environ)
        env.pop(DATA_KEYS_ENV, None)
        if keys:
            env[DATA_KEYS_ENV] = keys_to_env(keys)
        self.proc = subprocess.Popen(
            cmd, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, env=env
        )
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


def main(argv: list[str]) -> int:
    """Run one peer: ROLE N [ARG]."""
    run_peer(argv[0], int(argv[1]), argv[2] if len(argv) > 2 else "")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
