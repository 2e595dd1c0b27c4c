"""docs/protocol.md's data-stream statements a second implementation relies on, held to the
code (issue 30 item 9): the typed-port spellings, the HKDF info (its label not length-prefixed),
the receiver's longest encrypted record, no encryption on a Unix socket, `encrypt` in the
hello's policy, the data server's counters, and `bytes_in` on plain and encrypted streams. Raw
sockets play the foreign sender or receiver."""

from __future__ import annotations

import asyncio
import logging
import re
from collections.abc import AsyncIterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any, cast

import msgpack
import pytest
from cryptography.hazmat.primitives import hashes
from cryptography.hazmat.primitives.kdf.hkdf import HKDF

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.auth import DataAuth, proof_parts
from sdrpeer.dataplane.frames import FrameDecoder, Hello, encode_frame, encode_hello
from sdrpeer.dataplane.testing import RecordingPort
from sdrpeer.keys.derive import data_key, stream_keys
from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.sdk.robot_types import Pose
from sdrpeer.sdk.typed import message, message_type
from tests.test_dataplane_seal import stream_through
from tests.wait import until_async

DOC = Path(__file__).resolve().parents[1] / "docs" / "protocol.md"
K1 = data_key(b"\x01" * 32)
MIB = 1024 * 1024


def doc_text() -> str:
    """docs/protocol.md with every run of whitespace made one space."""
    return " ".join(DOC.read_text().split())


@message("demo/Sample")
@dataclass
class Sample:
    n: int
    ok: bool
    x: float
    label: str
    xs: list[float]
    ns: list[int]
    tags: list[str]
    extra: Any
    pose: Pose
    raw: bytes


def test_the_documented_field_spellings_and_type_id_are_the_codes() -> None:
    info = message_type(Sample)
    assert info is not None
    text = doc_text()
    (layout,) = re.findall(r"`demo/Sample\(([^)`]*)\)`", text)
    assert ";".join(f"{name}:{kind}" for name, kind in info.fields) == layout
    (documented,) = re.findall(r"id `(demo/Sample#[0-9a-f]{8})`", text)
    assert info.type_id == documented
    pose = message_type(Pose)
    assert pose is not None
    sample = Sample(
        1, True, 2.0, "a", [1.0], [2], ["t"], {"k": None}, Pose(1.0, "map", 2.0, 3.0), b"x"
    )
    assert info.flat(sample)[8] == pose.flat(sample.pose)  # a nested message: a nested array

    @dataclass
    class WithMap:
        m: dict[str, int]

    with pytest.raises(TypeError, match="must be float, int, bool, str, bytes"):
        message("demo/WithMap")(WithMap)  # no map type: a map travels in an `any` field


def test_the_hkdf_label_is_not_length_prefixed() -> None:
    label = b"sdrpeer data stream aes-256-gcm v1"
    assert f"the {len(label)} bytes `{label.decode()}` as they are" in doc_text()
    names = ("c1", "inp", "Pub.out", "s1", "1")
    info = label + b"".join(len(n).to_bytes(4, "big") + n.encode() for n in names)
    ns, nr = b"\xa0" * 16, b"\xb1" * 16
    both = HKDF(hashes.SHA256(), 64, ns + nr, info).derive(K1)
    assert stream_keys(K1, ns, nr, names) == (both[:32], both[32:])


class Raw:
    """A foreign sender on one socket: writes a hello, reads the reply, writes what it likes."""

    def __init__(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        self.reader, self.writer = reader, writer

    @classmethod
    async def open(cls, to: str) -> Raw:
        if to.startswith("unix://"):
            r, w = await asyncio.open_unix_connection(to.removeprefix("unix://"))
        else:
            host, port = to.removeprefix("tcp://").rsplit(":", 1)
            r, w = await asyncio.open_connection(host, int(port))
        return cls(r, w)

    async def hello(self, hello: Hello) -> dict[str, Any]:
        """Write `hello`; the reply map."""
        self.writer.write(encode_hello(hello))
        decoder = FrameDecoder()
        async with asyncio.timeout(10):
            while (reply := decoder.next_map()) is None:
                data = await self.reader.read(4096)
                assert data, "closed without a reply"
                decoder.feed(data)
        assert isinstance(reply, dict)
        return reply

    def prove(self, hello: Hello, reply: dict[str, Any], sealed: bool, then: bytes = b"") -> None:
        """Write our proof (and `then`, in the same write)."""
        assert hello.auth is not None
        nr = reply["auth"][0]
        proof = DataAuth.sender_proof(K1, nr, hello.auth, proof_parts(hello, sealed))
        self.writer.write(cast(bytes, msgpack.packb({"auth": proof})) + then)

    def close(self) -> None:
        self.writer.close()


@pytest.fixture
async def keyed() -> AsyncIterator[tuple[DataServer, RecordingPort]]:
    port = RecordingPort()
    server = DataServer(lambda name: port if name == "in" else None, auth=DataAuth([K1]))
    await server.start()
    yield server, port
    await server.close()


@pytest.mark.parametrize(("extra", "said"), [(1, "encrypted record of"), (0, "does not verify")])
async def test_the_receiver_takes_records_up_to_its_maximum_frame_plus_one_mib(
    caplog: pytest.LogCaptureFixture, extra: int, said: str
) -> None:
    """A record one byte over the limit is refused as soon as its length has arrived; one of
    exactly the limit is read whole (and then fails to verify: it is garbage)."""
    server = DataServer(lambda name: RecordingPort(), auth=DataAuth([K1]), max_frame=1024)
    await server.start()
    raw = await Raw.open(f"tcp://{server.addresses['tcp']}")
    try:
        caplog.set_level(logging.WARNING, "sdrpeer.dataplane")
        hello = Hello("c", "in", "x.out", {}, auth=DataAuth.nonce(), enc=True)
        reply = await raw.hello(hello)
        assert reply["enc"] is True
        n = 1024 + MIB + extra
        raw.prove(hello, reply, True, n.to_bytes(4, "big"))
        if not extra:
            raw.writer.write(bytes(n))
        await until_async(
            "refused_malformed", lambda: server.counters["refused_malformed"], lambda v: v == 1
        )
        assert said in caplog.text
    finally:
        raw.close()
        await server.close()


async def capture_hello(policy: ConnectorPolicy, unix: Path | None) -> dict[str, Any]:
    """The hello a keyed Python sender writes (to a raw receiver that refuses it)."""
    got: asyncio.Future[dict[str, Any]] = asyncio.get_running_loop().create_future()

    async def receive(r: asyncio.StreamReader, w: asyncio.StreamWriter) -> None:
        unpacker = msgpack.Unpacker(raw=False)
        while not got.done() and (data := await r.read(4096)):
            unpacker.feed(data)
            for obj in unpacker:
                if not got.done():
                    got.set_result(obj)
        w.write(cast(bytes, msgpack.packb({"ok": False, "error": "captured"})))
        w.close()

    if unix is not None:
        server = await asyncio.start_unix_server(receive, str(unix))
        to = f"unix://{unix}"
    else:
        server = await asyncio.start_server(receive, "127.0.0.1", 0)
        to = "tcp://{}:{}".format(*server.sockets[0].getsockname()[:2])
    conn = Connection("c", to, "in", "x.out", policy, auth=DataAuth([K1]))
    conn.start()
    try:
        async with asyncio.timeout(10):
            return await got
    finally:
        await conn.close()
        server.close()


async def test_a_sender_asks_for_encryption_on_tcp_only_and_says_when_it_does_not(
    tmp_path: Path,
) -> None:
    on = ConnectorPolicy(push="fifo")
    off = ConnectorPolicy(push="fifo", encrypt=False)
    tcp_on, tcp_off = await capture_hello(on, None), await capture_hello(off, None)
    assert (tcp_on["enc"], tcp_on["policy"]) == (True, {})
    assert ("enc" not in tcp_off, tcp_off["policy"]) == (True, {"encrypt": False})
    unix_on = await capture_hello(on, tmp_path / "rx.sock")
    assert "enc" not in unix_on
    assert unix_on["policy"] == {}  # nothing to say: a Unix socket is never encrypted
    assert len(unix_on["auth"]) == 16  # still authenticated


async def test_a_receiver_never_encrypts_a_unix_socket(tmp_path: Path) -> None:
    port = RecordingPort()
    path = tmp_path / "rx.sock"
    server = DataServer(lambda name: port, auth=DataAuth([K1]), unix_path=str(path))
    await server.start()
    raw = await Raw.open(f"unix://{path}")
    try:
        ns = DataAuth.nonce()
        hello = Hello("c", "in", "x.out", {}, auth=ns, enc=True)
        reply = await raw.hello(hello)
        assert reply["ok"] is True
        assert "enc" not in reply  # `enc` on a Unix socket is ignored
        nr, mac = reply["auth"]
        assert DataAuth([K1]).check_receiver(ns, nr, proof_parts(hello, False), mac) == K1
        raw.prove(hello, reply, False, encode_frame(1, "plain"))
        await until_async("a frame", lambda: port.values, lambda v: v == ["plain"])
    finally:
        raw.close()
        await server.close()


async def test_the_data_server_counts_what_the_table_says() -> None:
    acking = InPortRuntime("in", ConnectorPolicy("fifo", 100, "block"))
    server = DataServer(lambda name: acking if name == "in" else None)
    await server.start()
    to = f"tcp://{server.addresses['tcp']}"
    conn = Connection("c1", to, "in", "x.out", ConnectorPolicy("fifo", 100, "block"))
    conn.start()
    raws: list[Raw] = []
    try:
        conn.offer(1)
        await until_async("acked", lambda: server.counters["acked"], lambda v: v == 1)
        unknown = await Raw.open(to)
        raws.append(unknown)
        assert (await unknown.hello(Hello("c2", "nope", "x.out", {})))["ok"] is False
        bad_frame = await Raw.open(to)
        raws.append(bad_frame)
        assert (await bad_frame.hello(Hello("c3", "in", "x.out", {})))["ok"] is True
        bad_frame.writer.write(cast(bytes, msgpack.packb("not a frame")))
        await until_async(
            "refused_malformed", lambda: server.counters["refused_malformed"], lambda v: v == 1
        )
        not_hello = await Raw.open(to)
        raws.append(not_hello)
        not_hello.writer.write(cast(bytes, msgpack.packb({"v": 1})))
        await until_async(
            "refused_malformed", lambda: server.counters["refused_malformed"], lambda v: v == 2
        )
        counted = {k: server.counters[k] for k in ("accepted", "rejected", "acked")}
        assert counted == {"accepted": 4, "rejected": 1, "acked": 1}
    finally:
        for raw in raws:
            raw.close()
        await conn.close()
        await server.close()


async def test_bytes_in_is_every_byte_after_the_proof_even_in_the_proofs_read(
    keyed: tuple[DataServer, RecordingPort],
) -> None:
    """A foreign sender writes its proof and its first frame in one write: the frame's bytes
    count (they were left out when they came in the same read as the handshake)."""
    server, port = keyed
    raw = await Raw.open(f"tcp://{server.addresses['tcp']}")
    try:
        hello = Hello("c", "in", "x.out", {"encrypt": False}, auth=DataAuth.nonce())
        reply = await raw.hello(hello)
        frame = encode_frame(1, "x" * 100)
        raw.prove(hello, reply, False, frame)
        await until_async("a frame", lambda: len(port.frames), lambda v: v == 1)
        assert server.bytes_in["in"] == len(frame)
    finally:
        raw.close()


@pytest.mark.parametrize("encrypt", [True, False])
async def test_bytes_in_on_a_stream_is_what_travelled_after_the_handshake(encrypt: bool) -> None:
    """Through a relay that sees every byte: the receiver's `bytes_in` is all of them after
    the hello and the proof (records with their lengths and tags when encrypted)."""
    port, server, relay, conn = await stream_through(encrypt=encrypt)
    try:
        values = [b"v" * n for n in (10, 1000, 70_000, 300_000)]
        for v in values:
            conn.offer(v)
        await until_async("all frames", lambda: len(port.frames), lambda v: v == len(values))
        handshake = msgpack.Unpacker()
        handshake.feed(bytes(relay.seen))
        handshake.unpack(), handshake.unpack()  # the hello, then {"auth": MACs}
        after = len(relay.seen) - handshake.tell()
        assert server.bytes_in["in"] == after
        plain = sum(len(encode_frame(i + 1, v)) for i, v in enumerate(values))
        assert (after > plain) if encrypt else (after == plain)
    finally:
        await conn.close()
        await relay.close()
        await server.close()
