"""Authenticated data connections: keys prove themselves both ways; nothing else gets in."""

from __future__ import annotations

import asyncio
from collections.abc import AsyncIterator

import msgpack
import pytest

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.auth import DataAuth, proof_names, proof_parts
from sdrpeer.dataplane.frames import FrameDecoder, Hello, encode_hello
from sdrpeer.dataplane.testing import RecordingPort, make_policy
from sdrpeer.keys.datakeys import keys_from_env, keys_to_env
from sdrpeer.keys.derive import data_key
from tests.wait import stays_async, until_async

K1 = data_key(b"\x01" * 32)
K2 = data_key(b"\x02" * 32)


def test_keys_travel_as_hex_and_bad_ones_are_named() -> None:
    assert keys_from_env(keys_to_env([K1, K2])) == [K1, K2]
    assert keys_from_env("") == []
    assert K1 != K2
    assert len(K1) == 32
    with pytest.raises(ValueError, match="key 2 is not hex"):
        keys_from_env(f"{K1.hex()},zz")
    with pytest.raises(ValueError, match="key 1 must be 16 to 64 bytes"):
        keys_from_env("abcd")


def test_proofs_hold_only_under_the_same_key_and_names() -> None:
    a, b = DataAuth([K1]), DataAuth([K2, K1])
    sn, rn = a.nonce(), a.nonce()
    names = ("c", "in", "x.out", "session", "7")
    assert b.check_receiver(sn, rn, names, a.receiver_proof(sn, rn, names)) == K1
    assert DataAuth([K2]).check_receiver(sn, rn, names, a.receiver_proof(sn, rn, names)) is None
    moved = ("c", "in", "x.out", "session", "9")  # ack.next rewritten on the way
    assert b.check_receiver(sn, rn, moved, a.receiver_proof(sn, rn, names)) is None
    proof = DataAuth.sender_proof(K1, rn, sn, names)
    assert a.check_sender(rn, sn, names, proof)
    assert not a.check_sender(rn, sn, ("c", "in", "y.out", "session", "7"), proof)
    assert not a.check_sender(rn, sn, moved, proof)
    assert not a.check_sender(a.nonce(), sn, names, proof)  # another receiver nonce: a replay


def test_the_proofs_cover_whether_the_stream_is_encrypted() -> None:
    """A receiver's proof over what it saw ("clear": the flag stripped on the way) does not hold
    for the sender that asked for encryption, nor the sender's for the receiver."""
    a = DataAuth([K1])
    sn, rn = a.nonce(), a.nonce()
    hello = Hello("c", "in", "x.out", {}, auth=sn, enc=True)
    sealed, clear = proof_parts(hello, True), proof_parts(hello, False)
    assert sealed[:-1] == clear[:-1] == proof_names(hello)
    assert (sealed[-1], clear[-1]) == ("enc", "clear")
    assert a.check_receiver(sn, rn, sealed, a.receiver_proof(sn, rn, clear)) is None
    assert a.check_sender(rn, sn, clear, DataAuth.sender_proof(K1, rn, sn, sealed)) is None
    assert a.check_receiver(sn, rn, sealed, a.receiver_proof(sn, rn, sealed)) == K1


class Rx:
    def __init__(self, keys: list[bytes]) -> None:
        self.port = RecordingPort()
        self.server = DataServer(lambda name: self.port, auth=DataAuth(keys))

    @property
    def to(self) -> str:
        return f"tcp://{self.server.addresses['tcp']}"


@pytest.fixture
async def rx() -> AsyncIterator[Rx]:
    r = Rx([K1])
    await r.server.start()
    yield r
    await r.server.close()


async def send(to: str, keys: list[bytes] | None, n: int = 5) -> Connection:
    auth = DataAuth(keys) if keys is not None else None
    conn = Connection("c", to, "in", "x.out", make_policy("fifo", 64), auth=auth)
    conn.start()
    await asyncio.sleep(0)
    for i in range(n):
        conn.offer(i)
    return conn


async def test_a_sender_with_a_key_of_the_ring_gets_in(rx: Rx) -> None:
    conn = await send(rx.to, [K2, K1])  # signs with K2, still holds K1 (a rotation)
    try:
        await until_async("len(rx.port.frames) == 5", lambda: len(rx.port.frames), lambda v: v == 5)
        assert rx.port.values == [0, 1, 2, 3, 4]
        assert rx.server.counters["refused_auth"] == 0
    finally:
        await conn.close()


@pytest.mark.parametrize("keys", [None, [K2]])
async def test_a_sender_without_the_key_gets_nothing_in(rx: Rx, keys: list[bytes] | None) -> None:
    conn = await send(rx.to, keys)
    try:
        await until_async(
            "rx.server.counters['refused_auth'] > 0",
            lambda: rx.server.counters["refused_auth"],
            lambda v: v > 0,
        )
        await until_async("the sender told no", lambda: conn.connected, lambda up: not up)
        await stays_async(
            "nothing in, not connected",
            lambda: (rx.port.frames, conn.connected),
            lambda seen: seen == ([], False),
            window=0.05,
        )
        assert "authenticat" in (conn.last_error or "") or "proof" in (conn.last_error or "")
    finally:
        await conn.close()


async def test_a_sender_with_a_key_refuses_a_receiver_without_one() -> None:
    open_rx = Rx([])
    await open_rx.server.start()
    conn = await send(open_rx.to, [K1])
    try:
        await until_async(
            "conn.last_error is not None", lambda: conn.last_error, lambda v: v is not None
        )
        assert "did not authenticate" in (conn.last_error or "")
        assert open_rx.port.frames == []
    finally:
        await conn.close()
        await open_rx.server.close()


async def test_a_replayed_handshake_opens_nothing(rx: Rx) -> None:
    """A neighbour replays a legitimate hello and proof it captured: the receiver's nonce is
    new, so the old proof does not hold."""
    host, port = rx.server.addresses["tcp"].rsplit(":", 1)
    captured: list[bytes] = []

    async def handshake(proof: bytes | None) -> bytes | None:
        reader, writer = await asyncio.open_connection(host, int(port))
        nonce = DataAuth.nonce()
        hello = Hello("c", "in", "x.out", {"encrypt": False}, auth=nonce)  # clear: readable
        writer.write(encode_hello(hello))
        decoder = FrameDecoder()
        while (reply := decoder.next_map()) is None:
            decoder.feed(await reader.read(4096))
        assert isinstance(reply, dict)
        their_nonce = reply["auth"][0]
        names = ("c", "in", "x.out", "", "", "clear")
        made = proof or DataAuth.sender_proof(K1, their_nonce, nonce, names)
        writer.write(msgpack.packb({"auth": made}) + msgpack.packb([1, "frame"]))
        await writer.drain()
        captured.append(made)
        await asyncio.sleep(0.1)
        writer.close()
        return made

    await handshake(None)
    await until_async("len(rx.port.frames) == 1", lambda: len(rx.port.frames), lambda v: v == 1)
    await handshake(captured[0])  # the same proof, against a fresh receiver nonce
    await until_async(
        "rx.server.counters['refused_auth'] == 1",
        lambda: rx.server.counters["refused_auth"],
        lambda v: v == 1,
    )
    assert len(rx.port.frames) == 1
