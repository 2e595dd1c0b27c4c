"""The round-trip half of the data-plane benchmark: one client per contender, times per ping.

How it works: each function starts its echo peer (tools/dataplane_peers.py), then sends `m`
100-byte pings one at a time and times each until its pong is back (`time.perf_counter`); the
caller drops the first tenth (warm-up) and takes p50/p99. `sdr_pings` goes Connection ->
DataServer both ways (policy all); `svc_pings` is a service call (sdrpeer.sdk.services) over a
service binding, request and reply on one socket; `asyncio_pings` is a bare asyncio Protocol,
no framing: the floor under any design on asyncio's event loop.
"""

from __future__ import annotations

import asyncio
import socket
import time
from typing import Any

import zmq
from dataplane_peers import LEN, SERVICE, Peer, payload, recv_exact

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.service import ServiceClient
from sdrpeer.dataplane.testing import make_policy
from sdrpeer.sdk import Interface, ServiceCaller

SMALL = 100
"""Bytes per ping."""


async def sdr_pings(m: int) -> list[float]:
    """Round trips of sdrpeer: Connection -> the peer's DataServer, back the same way."""
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


async def svc_pings(m: int) -> list[float]:
    """Round trips of service calls: a `ServiceCaller` (the SDK's consumer port) bound to a
    `ServiceClient` calls `echo` on the peer's provided service (request and reply on one
    socket), timed from `call` until it returns the reply."""
    peer = await asyncio.to_thread(Peer, "svc-provider")
    interface = Interface.of(SERVICE, "echo")
    caller = ServiceCaller("svc", interface)
    to = f"tcp://{peer.addresses['tcp']}"
    client = ServiceClient("call", to, "svc", "bench.svc", interface.id)
    caller.bind(client)
    value, times = payload(SMALL), []
    await caller.call("echo", value, timeout=10)  # connected before the first timed call
    for _ in range(m):
        t0 = time.perf_counter()
        await caller.call("echo", value, timeout=10)
        times.append(time.perf_counter() - t0)
    await client.close()
    peer.stop()
    return times


async def asyncio_pings(m: int) -> list[float]:
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
        recv_exact(sock, len(frame))
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
