"""The receive buffer: big values taken out in place, everything else through msgpack."""

from __future__ import annotations

import os

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sdrpeer.dataplane.frames import encode_frame
from sdrpeer.dataplane.reader import BIG, READ_SIZE, FrameReader
from sdrpeer.errors import FrameError


def receive(reader: FrameReader, data: bytes, chunks: list[int]) -> list[list[object]]:
    """Push `data` through the reader in reads of the given sizes (cycled), like a socket."""
    out: list[list[object]] = []
    pos, i = 0, 0
    while pos < len(data):
        space = reader.buffer()
        n = min(len(space), chunks[i % len(chunks)], len(data) - pos)
        space[:n] = data[pos : pos + n]
        reader.received(n)
        pos += n
        i += 1
        out.extend(reader.frames())
    return out


VALUES: list[object] = [
    1,
    os.urandom(BIG),
    os.urandom(BIG - 1),
    "text",
    os.urandom(3 * READ_SIZE),  # bigger than the buffer: it grows
    {"nested": os.urandom(BIG)},  # big but not a bin at the top: msgpack
    os.urandom(200_000),
    None,
    os.urandom(200_000),
]
STREAM = b"".join(encode_frame(i + 1, v) for i, v in enumerate(VALUES))


@pytest.mark.parametrize(
    "chunks", [[1 << 30], [READ_SIZE], [1, 7, 15, 16, 17, 50_000], [65536], [999_983]]
)
def test_every_value_back_in_order(chunks: list[int]) -> None:
    frames = receive(FrameReader(16 << 20), STREAM, chunks)
    assert [f[0] for f in frames] == list(range(1, len(VALUES) + 1))
    assert [f[1] for f in frames] == VALUES
    assert all(type(f[1]) is bytes for f in frames if isinstance(f[1], bytes | bytearray))


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(1, 300_000), min_size=1, max_size=6).filter(lambda c: sum(c) > 9999))
def test_any_read_sizes(chunks: list[int]) -> None:
    frames = receive(FrameReader(16 << 20), STREAM, chunks)
    assert [f[1] for f in frames] == VALUES


def test_big_frame_over_the_maximum_refused_from_its_header() -> None:
    reader = FrameReader(100_000)
    data = encode_frame(1, b"ok") + encode_frame(2, os.urandom(150_000))
    assert receive(reader, data[:1000], [1000]) == [[1, b"ok"]]  # the big one taken back
    assert reader.failed
    with pytest.raises(FrameError) as info:
        reader.frames()
    assert info.value.reason == "oversized"


def test_hello_then_frames_in_the_same_read() -> None:
    reader = FrameReader(1 << 20)
    data = msgpack.packb({"v": 1}) + encode_frame(1, b"a") + encode_frame(2, os.urandom(BIG))
    space = reader.buffer()
    space[: len(data)] = data
    reader.received(len(data))
    assert reader.first_map() == {"v": 1}
    frames = reader.frames()
    assert [f[0] for f in frames] == [1, 2]


def test_many_small_frames_through_a_full_buffer() -> None:
    frames = [encode_frame(i, b"x" * 100) for i in range(1, 30001)]  # 3 MiB: buffer wraps
    got = receive(FrameReader(1 << 20), b"".join(frames), [READ_SIZE])
    assert [f[0] for f in got] == list(range(1, 30001))


def test_one_frame_per_read_and_its_checks() -> None:
    """A read that is exactly one small frame (the latency path) keeps every rule."""
    reader = FrameReader(1000)
    ping = encode_frame(7, b"p" * 100)
    for _ in range(3):
        assert receive(reader, ping, [len(ping)]) == [[7, b"p" * 100]]
    assert receive(reader, ping + ping[:5], [len(ping) + 5]) == [[7, b"p" * 100]]
    assert receive(reader, ping[5:], [1 << 20]) == [[7, b"p" * 100]]
    for bad, reason in [(encode_frame(1, b"x" * 2000), "oversized"), (b"\x93\x01\x02\x03", "")]:
        reader = FrameReader(1000)
        with pytest.raises(FrameError) as info:
            receive(reader, bad, [len(bad)])
        assert info.value.reason == (reason or "malformed")
