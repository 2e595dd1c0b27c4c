"""The data stream codec: hello/reply maps, frames, and the strict streaming decoder."""

from __future__ import annotations

from dataclasses import replace

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sdrpeer.dataplane.frames import (
    INCOMPLETE,
    AckOffer,
    FrameDecoder,
    Hello,
    big_frame_header,
    encode_frame,
    encode_hello,
    encode_reply,
    encode_value,
    frame_header,
    parse_hello,
    parse_reply,
)
from sdrpeer.errors import FrameError

HELLO = Hello("c1", "in", "cam.out", {"push": "all", "buffer": 8, "full": "overwrite", "skip": 0})


def decode_all(data: bytes, max_frame: int = 1 << 20, chunk: int = 7) -> list[list[object]]:
    decoder = FrameDecoder(max_frame)
    out: list[list[object]] = []
    for start in range(0, len(data), chunk):
        decoder.feed(data[start : start + chunk])
        out.extend(decoder.frames())
    return out


def test_hello_round_trip() -> None:
    decoder = FrameDecoder()
    decoder.feed(encode_hello(HELLO))
    assert parse_hello(decoder.next_map()) == HELLO
    assert decoder.next_map() is None
    typed = replace(HELLO, ack=AckOffer("s", 3, drops=True), type="sdrpeer/Pose#4a699e8d")
    assert parse_hello(msgpack.unpackb(encode_hello(typed))) == typed
    old = replace(HELLO, ack=AckOffer("s", 3))  # a sender that does not read drop counts
    assert "drops" not in msgpack.unpackb(encode_hello(old))["ack"]


@pytest.mark.parametrize(
    ("obj", "problem"),
    [
        ([1, 2], "expected a map"),
        ({"v": 1, "in": "x", "from": "a.b"}, "'conn'"),
        ({"v": "1", "conn": "c", "in": "x", "from": "a.b"}, "'v'"),
        ({"v": 1, "conn": "c", "in": "x", "from": "a.b", "policy": 3}, "'policy'"),
        ({"v": 1, "conn": "c", "in": "x", "from": "a.b", "type": 7}, "'type'"),
        ({"v": 1, "conn": "c", "in": "x", "from": "a.b", "type": "t" * 121}, "'type'"),
        (
            {
                "v": 1,
                "conn": "c",
                "in": "x",
                "from": "a.b",
                "ack": {"session": "s", "next": 1, "drops": 1},
            },
            "'ack.drops'",
        ),
    ],
)
def test_bad_hello_is_malformed(obj: object, problem: str) -> None:
    with pytest.raises(FrameError, match=problem) as info:
        parse_hello(obj)
    assert info.value.reason == "malformed"


def test_reply_round_trip() -> None:
    assert parse_reply(msgpack.unpackb(encode_reply(None))) is None
    error = "unknown in-port 'x'"
    assert parse_reply(msgpack.unpackb(encode_reply(error))) == error
    with pytest.raises(FrameError):
        parse_reply({"ok": "yes"})


@pytest.mark.parametrize("seq", [1, 127, 128, 65536, 2**32 - 1, 2**32, 2**64 - 1])
def test_frame_header_is_msgpack_uint(seq: int) -> None:
    assert msgpack.unpackb(encode_frame(seq, b"v")) == [seq, b"v"]
    assert len(frame_header(seq)) <= 10


def test_frames_in_order_across_any_chunking() -> None:
    data = b"".join(encode_frame(i, {"i": i, "b": b"x" * i}) for i in range(1, 200))
    for chunk in (1, 3, 100, 4096, len(data)):
        frames = decode_all(data, chunk=chunk)
        assert [f[0] for f in frames] == list(range(1, 200))
        assert frames[5][1] == {"i": 6, "b": b"x" * 6}


@pytest.mark.parametrize(
    "obj", [[1], [1, 2, 3], [-1, b"x"], ["1", b"x"], [1.0, b"x"], {"seq": 1}, 5, b"raw", None]
)
def test_non_frame_shapes_are_malformed(obj: object) -> None:
    decoder = FrameDecoder()
    decoder.feed(msgpack.packb(obj))
    with pytest.raises(FrameError) as info:
        decoder.frames()
    assert info.value.reason == "malformed"


def test_complete_frame_over_the_maximum_is_oversized() -> None:
    decoder = FrameDecoder(max_frame=1000)
    decoder.feed(encode_frame(1, b"a" * 10) + encode_frame(2, b"b" * 2000))
    assert decoder.frames() == [[1, b"a" * 10]]  # the good frame before the bad one
    assert decoder.failed
    with pytest.raises(FrameError) as info:
        decoder.frames()
    assert info.value.reason == "oversized"
    with pytest.raises(FrameError):
        decoder.frames()  # the stream stays broken


def test_frame_still_arriving_over_the_maximum_is_oversized() -> None:
    decoder = FrameDecoder(max_frame=1000)
    frame = encode_frame(1, list(range(2000)))  # many small items: consumed as they arrive
    decoder.feed(frame[:1500])
    with pytest.raises(FrameError) as info:
        decoder.frames()
    assert info.value.reason == "oversized"


def test_huge_declared_bin_cannot_grow_the_buffer() -> None:
    decoder = FrameDecoder(max_frame=1000)
    decoder.feed(b"\x92\x01\xc6\x7f\xff\xff\xff")  # a 2 GiB bin announced
    assert decoder.frames() == []

    def flood() -> None:
        for _ in range(100):
            decoder.feed(b"\0" * 65536)
            decoder.frames()

    with pytest.raises(FrameError) as info:
        flood()
    assert info.value.reason == "oversized"


def test_deep_nesting_and_bad_utf8_are_malformed() -> None:
    for data in (b"\x92\x01" + b"\x91" * 5000 + b"\x01", b"\x92\x01\xa2\xff\xfe"):
        decoder = FrameDecoder()
        decoder.feed(data)
        with pytest.raises(FrameError):
            decoder.frames()


def test_unencodable_value() -> None:
    with pytest.raises(FrameError) as info:
        encode_value(object())
    assert info.value.reason == "unencodable"


def _only_frame_errors(data: bytes, chunk: int, hello_first: bool) -> None:
    decoder = FrameDecoder(max_frame=4096)
    reason = "none"
    try:
        for start in range(0, len(data), chunk):
            decoder.feed(data[start : start + chunk])
            if hello_first:
                if decoder.next_map() is None:
                    continue
                hello_first = False
            decoder.frames()
    except FrameError as exc:
        reason = exc.reason
    assert reason in ("none", "oversized", "malformed")


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=3000), st.integers(1, 600), st.booleans())
def test_fuzz_random_bytes_raise_only_frame_errors(data: bytes, chunk: int, hello: bool) -> None:
    _only_frame_errors(data, chunk, hello)


msgpack_values = st.recursive(
    st.none()
    | st.booleans()
    | st.integers(-(2**63), 2**64 - 1)
    | st.floats()
    | st.text(max_size=20)
    | st.binary(max_size=50),
    lambda inner: st.lists(inner, max_size=5) | st.dictionaries(st.text(max_size=5), inner),
    max_leaves=20,
)


@settings(max_examples=300, deadline=None)
@given(st.lists(msgpack_values, max_size=8), st.integers(0, 400), st.integers(1, 64), st.binary())
def test_fuzz_truncated_and_corrupted_streams(
    values: list[object], cut: int, chunk: int, noise: bytes
) -> None:
    data = b"".join(encode_frame(i + 1, v) for i, v in enumerate(values))
    _only_frame_errors(data[:cut] + noise, chunk, hello_first=False)
    frames = decode_all(data, max_frame=1 << 20, chunk=chunk)  # intact: every frame back
    assert [f[0] for f in frames] == list(range(1, len(values) + 1))


@pytest.mark.parametrize(
    ("data", "expected"),
    [
        (encode_frame(7, b"x" * 70000)[:16], (7, 11, 70000)),
        (b"\x92\x07\xc6\x00\x01\x11\x70", (7, 7, 70000)),
        (encode_frame(2**40, b"x" * 70000)[:16], (2**40, 15, 70000)),
        (b"\x92\xcc\x05\xc5\xff\xff", None),  # a bin16 of 65535 bytes: under the minimum
        (encode_frame(7, b"x" * 100)[:16], None),  # small value: msgpack decodes it
        (encode_frame(7, "x" * 70000)[:16], None),  # a str, not a bin
        (encode_frame(7, b"x" * 70000)[:4], INCOMPLETE),  # may still be big
        (encode_frame(7, b"x" * 70000)[:8], INCOMPLETE),
        (b"\x92", INCOMPLETE),
        (b"\x92\x01\x01", None),
        (b"\x93\x01\xc6\x00\x01\x00\x00", None),  # not a 2-array
        (b"\x92\xd0\x01\xc6\x00\x01\x00\x00", None),  # signed seq
    ],
)
def test_big_frame_header(data: bytes, expected: tuple[int, int, int] | None) -> None:
    assert big_frame_header(data, 65536) == expected
