"""Encrypted data streams: records open only in order and unaltered, and a stream between two
keyed hosts over TCP carries no payload byte in clear; an altered byte breaks the stream
instead of delivering a changed value. A TCP relay between sender and receiver is the
eavesdropper (and, tampering, the on-path attacker)."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import Callable
from typing import Any, cast

import msgpack
import pytest

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.frames import FrameDecoder, Hello, encode_hello
from sdrpeer.dataplane.seal import OVERHEAD, Opener, Sealer
from sdrpeer.dataplane.testing import RecordingPort
from sdrpeer.errors import FrameError
from sdrpeer.keys.derive import data_key, stream_keys
from sdrpeer.sdk.policy import ConnectorPolicy
from tests.wait import until_async

K1 = data_key(b"\x01" * 32)
PATTERN = b"SECRET-FRAME-PAYLOAD-"


def test_records_open_in_order_in_any_pieces_and_refuse_changes() -> None:
    send, back = stream_keys(K1, b"s" * 16, b"r" * 16, ("c", "in", "x.out", "", ""))
    assert send != back
    sealer, opener = Sealer(send), Opener(send, 1 << 20)
    records = b"".join(b"".join(sealer.seal(m)) for m in (b"one", b"", b"three" * 1000))
    assert len(records) == 3 + 0 + 5000 + 3 * OVERHEAD
    out: list[bytes] = []
    for i in range(0, len(records), 7):  # any split of the byte stream
        out += opener.open(records[i : i + 7])
    assert out == [b"one", b"", b"three" * 1000]
    one, two = b"".join(Sealer(send).seal(b"a")), b"".join(Sealer(send).seal(b"b"))
    with pytest.raises(FrameError, match="does not verify"):
        Opener(send, 1 << 20).open(one + two)  # the second reuses counter 1: a replay
    fresh = Sealer(send)
    first, second = b"".join(fresh.seal(b"a")), b"".join(fresh.seal(b"b"))
    with pytest.raises(FrameError, match="does not verify"):
        Opener(send, 1 << 20).open(second + first)  # reordered
    with pytest.raises(FrameError, match="does not verify"):
        Opener(back, 1 << 20).open(b"".join(Sealer(send).seal(b"a")))  # the other direction
    with pytest.raises(FrameError, match="record of"):
        Opener(send, 100).open(b"".join(Sealer(send).seal(b"x" * 200)))  # longer than allowed


class Relay:
    """A TCP relay sender -> receiver that records (and may alter) what passes one way."""

    def __init__(self, to: str, alter: Callable[[int, bytes], bytes] = lambda at, b: b) -> None:
        self.to = to
        self.alter = alter
        self.seen = bytearray()
        self.server: asyncio.Server | None = None
        self.writers: list[asyncio.StreamWriter] = []
        self.handlers: set[asyncio.Task[object]] = set()

    async def start(self) -> str:
        self.server = await asyncio.start_server(self._relay, "127.0.0.1", 0)
        host, port = self.server.sockets[0].getsockname()[:2]
        return f"tcp://{host}:{port}"

    async def _relay(self, r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        task = asyncio.current_task()
        assert task is not None
        self.handlers.add(task)
        self.writers.append(w)
        host, port = self.to.removeprefix("tcp://").rsplit(":", 1)
        r2, w2 = await asyncio.open_connection(host, int(port))
        self.writers.append(w2)

        async def pipe(src: asyncio.StreamReader, dst: asyncio.StreamWriter, tap: bool) -> None:
            while data := await src.read(65536):
                if tap:
                    data = self.alter(len(self.seen), data)
                    self.seen += data
                dst.write(data)
                await dst.drain()
            dst.close()

        await asyncio.gather(pipe(r, w2, True), pipe(r2, w, False), return_exceptions=True)

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
        for task in self.handlers:
            task.cancel()
        await asyncio.gather(*self.handlers, return_exceptions=True)
        for w in self.writers:
            w.close()
            with contextlib.suppress(ConnectionError):
                await w.wait_closed()


async def stream_through(
    relay_alter: Callable[[int, bytes], bytes] | None = None, *, encrypt: bool = True
) -> tuple[RecordingPort, DataServer, Relay, Connection]:
    port = RecordingPort()
    server = DataServer(lambda name: port, auth=DataAuth([K1]))
    await server.start()
    relay = Relay(f"tcp://{server.addresses['tcp']}", relay_alter or (lambda at, b: b))
    to = await relay.start()
    policy = ConnectorPolicy(push="fifo", buffer=256, encrypt=encrypt)
    conn = Connection("c", to, "in", "x.out", policy, auth=DataAuth([K1]))
    conn.start()
    return port, server, relay, conn


async def test_a_keyed_tcp_stream_shows_no_payload_to_an_eavesdropper() -> None:
    port, server, relay, conn = await stream_through()
    try:
        values = [PATTERN + bytes([i]) * 80 for i in range(50)] + [PATTERN * 20_000]
        for v in values:
            conn.offer(v)
        await until_async(
            "len(port.frames) == len(values)", lambda: len(port.frames), lambda v: v == len(values)
        )
        assert port.values == values
        assert len(relay.seen) > sum(map(len, values))  # everything passed the relay...
        assert PATTERN not in relay.seen  # ...and none of it in clear
        assert b"SECRET" not in relay.seen
    finally:
        await conn.close()
        await relay.close()
        await server.close()


async def test_an_altered_byte_breaks_the_stream_and_delivers_nothing_changed() -> None:
    def flip(at: int, data: bytes) -> bytes:
        if at <= 3000 < at + len(data):  # one byte, well after the handshake
            i = 3000 - at
            return data[:i] + bytes([data[i] ^ 0x01]) + data[i + 1 :]
        return data

    port, server, relay, conn = await stream_through(flip)
    try:
        values = [PATTERN + bytes([i]) * 200 for i in range(60)]
        for v in values:
            conn.offer(v)
        await until_async(
            "server.counters['refused_malformed'] >= 1",
            lambda: server.counters["refused_malformed"],
            lambda v: v >= 1,
        )
        assert all(v in values for v in port.values)  # what came is what was sent
        assert len(port.values) < len(values)  # the broken record was not delivered
    finally:
        await conn.close()
        await relay.close()
        await server.close()


async def test_a_connection_may_turn_encryption_off_and_stays_authenticated() -> None:
    """`encrypt: false` in a connection's policy (or the system's `streams:`): the stream is in
    clear (what an operator trades for throughput on a bulk link), still only between keys."""
    port, server, relay, conn = await stream_through(encrypt=False)
    try:
        conn.offer(PATTERN * 10)
        await until_async("len(port.frames) == 1", lambda: len(port.frames), lambda v: v == 1)
        assert PATTERN in relay.seen
        assert server.counters["refused_auth"] == 0
    finally:
        await conn.close()
        await relay.close()
        await server.close()


async def raw_handshake(to: str, hello: Hello) -> dict[str, object]:
    """Write `hello` to the receiver at `to` as a foreign sender would; its reply map."""
    host, port = to.removeprefix("tcp://").rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    try:
        writer.write(encode_hello(hello))
        decoder = FrameDecoder()
        async with asyncio.timeout(10):
            while (reply := decoder.next_map()) is None:
                data = await reader.read(4096)
                assert data, "the receiver closed without a reply"
                decoder.feed(data)
        assert isinstance(reply, dict)
        return reply
    finally:
        writer.close()


async def test_a_keyed_receiver_refuses_a_sender_that_does_not_ask_for_encryption() -> None:
    """Issue 30 item 3: an old foreign sender wrote an authenticated hello without "enc" and
    the receiver took its stream in clear. Now it is refused, said and counted, unless the
    connection's own policy says encrypt: false (what the Python sender then writes)."""
    port = RecordingPort()
    server = DataServer(lambda name: port, auth=DataAuth([K1]))
    await server.start()
    to = f"tcp://{server.addresses['tcp']}"
    try:
        reply = await raw_handshake(to, Hello("c", "in", "x.out", {}, auth=DataAuth.nonce()))
        assert reply["ok"] is False
        assert "only takes encrypted streams" in str(reply["error"])
        assert "auth" not in reply  # no proof for a refused hello
        assert server.counters["refused_clear"] == 1
        said = Hello("c", "in", "x.out", {"encrypt": False}, auth=DataAuth.nonce())
        reply = await raw_handshake(to, said)
        assert reply["ok"] is True
        assert "enc" not in reply
        assert server.counters["refused_clear"] == 1
    finally:
        await server.close()


def rewrite_hello(change: Callable[[dict[str, Any]], None]) -> Callable[[int, bytes], bytes]:
    """A relay's `alter` that rewrites the hello (the first map on the stream) with `change`."""

    def alter(at: int, data: bytes) -> bytes:
        if at != 0:
            return data
        unpacker = msgpack.Unpacker(raw=False)
        unpacker.feed(data)
        hello = unpacker.unpack()
        change(hello)
        return cast(bytes, msgpack.packb(hello)) + data[unpacker.tell() :]

    return alter


def strip_enc(hello: dict[str, Any]) -> None:
    hello.pop("enc", None)
    hello["policy"] = {**hello["policy"], "encrypt": False}


def add_enc(hello: dict[str, Any]) -> None:
    hello["enc"] = True
    hello["policy"] = {}


@pytest.mark.parametrize(("encrypt", "change"), [(True, strip_enc), (False, add_enc)])
async def test_a_flag_flipped_in_flight_fails_the_proof(
    encrypt: bool, change: Callable[[dict[str, Any]], None]
) -> None:
    """A man in the middle rewrites the hello's encryption (and the policy's `encrypt` to
    match, so the receiver has nothing to object to): the receiver's proof covers what it saw,
    the sender checks it against what it sent, and refuses it; no frame gets through."""
    port, server, relay, conn = await stream_through(rewrite_hello(change), encrypt=encrypt)
    try:
        conn.offer(PATTERN)
        await until_async(
            "conn.last_error names the proof",
            lambda: conn.last_error or "",
            lambda v: "proof does not hold" in v,
        )
        await until_async(
            "server.counters['refused_auth'] >= 1",
            lambda: server.counters["refused_auth"],
            lambda v: v >= 1,
        )
        assert port.frames == []
        assert not conn.connected
    finally:
        await conn.close()
        await relay.close()
        await server.close()
