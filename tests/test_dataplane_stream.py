"""Data streams over real sockets: hello, ordered frames, repoint, reconnect, bad frames."""

from __future__ import annotations

import asyncio
import os
import socket
from collections.abc import AsyncIterator
from pathlib import Path

import msgpack
import pytest

from sdrpeer.dataplane import Connection, DataServer, FrameError
from sdrpeer.dataplane.frames import Hello, encode_frame, encode_hello
from sdrpeer.dataplane.testing import RecordingPort, make_policy
from tests.wait import until_async


class Receiver:
    """A DataServer with one InPort named "in"."""

    def __init__(self, unix_path: Path | None = None, **kw: int) -> None:
        self.port = RecordingPort()
        self.server = DataServer(
            lambda name: self.port if name == "in" else None,
            unix_path=None if unix_path is None else str(unix_path),
            **kw,  # type: ignore[arg-type]
        )

    def address(self, kind: str) -> str:
        return f"{kind}://{self.server.addresses[kind]}"


@pytest.fixture
async def receiver(tmp_path: Path) -> AsyncIterator[Receiver]:
    rx = Receiver(tmp_path / "rx.sock")
    await rx.server.start()
    yield rx
    await rx.server.close()


def connect(to: str, **policy: object) -> Connection:
    conn = Connection("c1", to, "in", "cam.out", make_policy(**policy))  # type: ignore[arg-type]
    conn.start()
    return conn


async def offer_all(conn: Connection, values: range) -> None:
    for value in values:
        while not conn.offer(value):
            await conn.drain()


async def raw_hello(address: tuple[str, int], in_port: str) -> tuple[socket.socket, object]:
    sock = socket.create_connection(address, timeout=5)
    sock.sendall(encode_hello(Hello("raw", in_port, "x.y", {})))
    unpacker = msgpack.Unpacker()
    while True:
        unpacker.feed(await asyncio.to_thread(sock.recv, 4096))
        for reply in unpacker:
            return sock, reply


def tcp_target(rx: Receiver) -> tuple[str, int]:
    host, port = rx.server.addresses["tcp"].rsplit(":", 1)
    return host, int(port)


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_frames_arrive_in_order_with_seq(receiver: Receiver, kind: str) -> None:
    conn = connect(receiver.address(kind), push="fifo", buffer=64, full="block")
    await offer_all(conn, range(1, 2001))
    await until_async(
        "len(receiver.port.frames) == 2000", lambda: len(receiver.port.frames), lambda v: v == 2000
    )
    assert receiver.port.seqs == list(range(1, 2001))
    assert receiver.port.values == list(range(1, 2001))
    assert {c for _, _, c in receiver.port.frames} == {"c1"}
    assert (conn.frames_out, conn.seq, conn.dropped) == (2000, 2000, 0)
    assert receiver.server.bytes_in["in"] == conn.bytes_out
    await conn.close()


async def test_hello_ok_and_unknown_port_error(receiver: Receiver) -> None:
    sock, reply = await raw_hello(tcp_target(receiver), "in")
    assert reply == {"ok": True}
    sock.close()
    sock, reply = await raw_hello(tcp_target(receiver), "nope")
    assert reply == {"ok": False, "error": "unknown in-port 'nope'"}
    assert await asyncio.to_thread(sock.recv, 10) == b""  # closed after the error
    sock.close()

    conn = Connection(
        "c2", receiver.address("tcp"), "nope", "a.b", make_policy(), backoff=(0.01, 0.05)
    )
    conn.start()
    await until_async(
        "conn.last_error is not None", lambda: conn.last_error, lambda v: v is not None
    )
    assert "unknown in-port 'nope'" in (conn.last_error or "")
    assert not conn.connected
    await conn.close()


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_repoint_live_connection_loses_nothing(tmp_path: Path, kind: str) -> None:
    first, second = Receiver(tmp_path / "a.sock"), Receiver(tmp_path / "b.sock")
    await first.server.start()
    await second.server.start()
    conn = connect(first.address(kind), push="fifo", buffer=32, full="block")
    total = 20000
    sender = asyncio.create_task(offer_all(conn, range(1, total + 1)))
    await until_async(
        "len(first.port.frames) > 2000", lambda: len(first.port.frames), lambda v: v > 2000
    )
    conn.repoint(second.address(kind))
    await asyncio.wait_for(sender, 10)
    await until_async(
        "len(first.port.frames) + len(second.port.frames) >= total",
        lambda: len(first.port.frames) + len(second.port.frames),
        lambda v: v >= total,
    )
    seqs = first.port.seqs + second.port.seqs
    assert sorted(seqs) == list(range(1, total + 1))  # no gap, no duplicate
    assert second.port.seqs[0] == first.port.seqs[-1] + 1  # seq continues
    assert 0 < len(second.port.frames) < total
    assert first.port.values + second.port.values == list(range(1, total + 1))
    await conn.close()
    await first.server.close()
    await second.server.close()


async def test_reconnect_after_receiver_restart(tmp_path: Path) -> None:
    path = tmp_path / "rx.sock"
    rx = Receiver(path)
    await rx.server.start()
    conn = Connection(
        "c1", f"unix://{path}", "in", "a.b", make_policy("fifo", 64, "block"), backoff=(0.01, 0.1)
    )
    conn.start()
    await offer_all(conn, range(1, 101))
    await until_async("len(rx.port.frames) == 100", lambda: len(rx.port.frames), lambda v: v == 100)
    await rx.server.close()
    await until_async("not conn.connected", lambda: not conn.connected)
    await offer_all(conn, range(101, 111))  # queued while the receiver is away
    rx2 = Receiver(path)
    await rx2.server.start()
    await until_async("len(rx2.port.frames) == 10", lambda: len(rx2.port.frames), lambda v: v == 10)
    assert rx2.port.values == list(range(101, 111))
    assert rx2.port.seqs == list(range(101, 111))  # seq continues on the new link
    assert conn.reconnects == 1
    await conn.close()
    await rx2.server.close()


@pytest.mark.parametrize(
    ("bad", "reason"),
    [
        (msgpack.packb({"not": "a frame"}), "refused_malformed"),
        (msgpack.packb(["1", b"x"]), "refused_malformed"),
        (b"\xc1", "refused_malformed"),  # never-used msgpack byte
        (encode_frame(2, b"x" * 5000), "refused_oversized"),
    ],
)
async def test_bad_frame_refused_counted_closed_others_unaffected(
    tmp_path: Path, bad: bytes, reason: str
) -> None:
    rx = Receiver(max_frame=4096)
    await rx.server.start()
    good = connect(rx.address("tcp"), push="fifo", buffer=64, full="block")
    await offer_all(good, range(1, 11))
    sock, reply = await raw_hello(tcp_target(rx), "in")
    assert reply == {"ok": True}
    sock.sendall(encode_frame(1, b"fine") + bad)
    try:
        rest = await asyncio.to_thread(sock.recv, 10)
    except ConnectionResetError:
        rest = b""
    assert rest == b""  # the receiver closed this connection
    sock.close()
    assert rx.server.counters[reason] == 1
    assert rx.port.refused == 1
    await offer_all(good, range(11, 21))
    await until_async("len(rx.port.frames) == 21", lambda: len(rx.port.frames), lambda v: v == 21)
    assert [v for v in rx.port.values if v != b"fine"] == list(range(1, 21))
    await good.close()
    await rx.server.close()


async def test_oversized_value_refused_at_offer(receiver: Receiver) -> None:
    conn = Connection("big", receiver.address("tcp"), "in", "a.b", make_policy(), max_frame=1000)
    with pytest.raises(FrameError, match=r"connection big .*exceeds the maximum 1000") as info:
        conn.offer(b"x" * 2000)
    assert info.value.reason == "oversized"
    assert (conn.refused, conn.pending, conn.seq) == (1, 0, 0)
    await conn.close()


async def test_connection_limit(tmp_path: Path) -> None:
    rx = Receiver(max_connections=1)
    await rx.server.start()
    first, reply = await raw_hello(tcp_target(rx), "in")
    assert reply == {"ok": True}
    second, reply = await raw_hello(tcp_target(rx), "in")
    assert reply == {"ok": False, "error": "too many connections (max 1)"}
    first.close()
    second.close()
    await rx.server.close()


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_big_and_small_values_mixed_arrive_intact(receiver: Receiver, kind: str) -> None:
    big = [os.urandom(size) for size in (65536, 70001, 1_000_000, 3_000_000)]
    values: list[object] = [1, big[0], big[1], "s", big[2], big[2], {"k": big[3]}, big[3], b"x", 2]
    conn = connect(receiver.address(kind), push="fifo", buffer=4, full="block")
    await offer_all_values(conn, values)
    await until_async(
        "len(receiver.port.frames) == len(values)",
        lambda: len(receiver.port.frames),
        lambda v: v == len(values),
    )
    assert receiver.port.values == values
    assert receiver.port.seqs == list(range(1, len(values) + 1))
    await conn.close()


async def test_big_value_header_split_from_its_bytes(receiver: Receiver) -> None:
    sock, reply = await raw_hello(tcp_target(receiver), "in")
    assert reply == {"ok": True}
    value = os.urandom(100_000)
    frame = encode_frame(1, value) + encode_frame(2, value) + encode_frame(3, "end")
    for cut in (3, 9, 5000, 100_005, 100_011, 150_000, len(frame)):  # header, body, next header
        sock.sendall(frame[:cut])
        frame = frame[cut:]
        await asyncio.sleep(0.01)
    await until_async(
        "len(receiver.port.frames) == 3", lambda: len(receiver.port.frames), lambda v: v == 3
    )
    assert receiver.port.values == [value, value, "end"]
    sock.close()


async def test_big_value_over_the_maximum_refused() -> None:
    rx = Receiver(max_frame=100_000)
    await rx.server.start()
    sock, _ = await raw_hello(tcp_target(rx), "in")
    sock.sendall(encode_frame(1, b"ok") + encode_frame(2, os.urandom(150_000)))
    await until_async(
        "rx.server.counters['refused_oversized'] == 1",
        lambda: rx.server.counters["refused_oversized"],
        lambda v: v == 1,
    )
    assert rx.port.values == [b"ok"]
    assert rx.port.refused == 1
    sock.close()
    await rx.server.close()


async def offer_all_values(conn: Connection, values: list[object]) -> None:
    for value in values:
        while not conn.offer(value):
            await conn.drain()
