"""The host side's pure core: decoding commands, refusals, limits, parts."""

from __future__ import annotations

import msgpack
import pytest

from sdrpeer.control.codec import to_map
from sdrpeer.control.host_side import ControlDecoder, Refusal, Request
from sdrpeer.control.messages import Activate, Exit, Reset, Restore, SetParams
from sdrpeer.control.parts import parts
from sdrpeer.control.stream import MAX_MESSAGE
from sdrpeer.errors import ProtocolError


def pack(value: object) -> bytes:
    return msgpack.packb(value, use_bin_type=True)  # type: ignore[no-any-return]


def test_commands_across_arbitrary_cuts() -> None:
    stream = pack({"t": "activate", "id": 1}) + pack({"t": "exit", "id": 2, "timeout": 1.5})
    for cut in range(len(stream) + 1):
        decoder = ControlDecoder()
        got = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert got == [Request(1, Activate()), Request(2, Exit(1.5))]


@pytest.mark.parametrize(
    ("value", "why"),
    [
        ([1, 2], "expected a map, got list"),
        ("activate", "expected a map, got str"),
        ({"id": 1}, "without a str 't'"),
        ({"t": 5, "id": 1}, "without a str 't'"),
    ],
)
def test_not_a_map_with_str_t_is_a_protocol_error(value: object, why: str) -> None:
    with pytest.raises(ProtocolError, match=why):
        ControlDecoder().feed(pack(value))


def test_garbage_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="undecodable"):
        ControlDecoder().feed(b"\xc1" * 4)


def test_exactly_the_limit_passes_one_byte_more_fails() -> None:
    limit = 1000
    blob = b"x" * 300
    msg = pack({"t": "set_params", "id": 1, "params": {"blob": blob}})
    pad = limit - len(msg)
    msg = pack({"t": "set_params", "id": 1, "params": {"blob": blob + b"x" * pad}})
    assert len(msg) == limit
    (request,) = ControlDecoder(max_message=limit).feed(msg)
    assert isinstance(request, Request)
    assert isinstance(request.command, SetParams)
    bigger = pack({"t": "set_params", "id": 1, "params": {"blob": blob + b"x" * (pad + 1)}})
    with pytest.raises(ProtocolError, match="limit 1000"):
        ControlDecoder(max_message=limit).feed(bigger)


def test_a_huge_message_fails_before_it_is_buffered() -> None:
    header = b"\xc6" + (50 << 20).to_bytes(4, "big")  # bin32 of 50 MiB
    with pytest.raises(ProtocolError, match="over"):
        ControlDecoder().feed(header + bytes(MAX_MESSAGE + 100_000))


def test_many_small_messages_in_one_read_are_fine() -> None:
    stream = b"".join(pack({"t": "activate", "id": i, "pad": "x" * 100}) for i in range(20000))
    assert len(stream) > 2 * MAX_MESSAGE
    assert [c.id for c in ControlDecoder().feed(stream)] == list(range(20000))


def test_map_without_integer_id_is_counted_and_skipped() -> None:
    decoder = ControlDecoder()
    stream = pack({"t": "activate"}) + pack({"t": "activate", "id": True})
    assert decoder.feed(stream + pack({"t": "reset", "id": 3})) == [Request(3, Reset())]
    assert decoder.ignored == 2


@pytest.mark.parametrize(
    ("command", "error"),
    [
        ({"t": "dance", "id": 1}, "unknown command 'dance'"),
        ({"t": "set_params", "id": 1}, "set_params: no 'params'"),
        (
            {"t": "set_params", "id": 1, "params": [1]},
            "set_params: 'params' must be a map, got [1]",
        ),
        ({"t": "connect", "id": 1, "conn": "c"}, "connect: 'conn' must be a map, got 'c'"),
        ({"t": "connect", "id": 1, "conn": {"id": "c"}}, "connect: no 'conn.out'"),
        ({"t": "disconnect", "id": 1, "conn_id": 5}, "disconnect: 'conn_id' must be a string"),
        ({"t": "data_keys", "id": 1, "keys": [1]}, "data_keys: 'keys' must be a list of strings"),
        ({"t": "exit", "id": 1, "timeout": "soon"}, "exit: 'timeout' must be a number"),
        ({"t": "snapshot", "id": 1, "max": 1.5}, "snapshot: 'max' must be an integer"),
        ({"t": "restore", "id": 1}, "restore: no 'size'"),
    ],
)
def test_a_command_the_codec_cannot_read_is_refused_not_fatal(
    command: dict[str, object], error: str
) -> None:
    decoder = ControlDecoder()
    (refusal,) = decoder.feed(pack(command))
    assert isinstance(refusal, Refusal)
    assert (refusal.id, refusal.t) == (1, command["t"])
    assert refusal.error.startswith(error)
    assert decoder.feed(pack({"t": "activate", "id": 2})) == [Request(2, Activate())]


def test_parts_before_a_command_become_its_blob() -> None:
    blob = bytes(range(256)) * 2000  # 512000 bytes: two parts
    stream = b"".join(pack(to_map(m)) for m in parts(7, blob))
    stream += pack({"t": "restore", "id": 7, "size": len(blob)})
    for cut in (0, 1, 100_000, len(stream) - 1):
        decoder = ControlDecoder()
        got = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert got == [Request(7, Restore(len(blob)), blob)]


@pytest.mark.parametrize(
    ("stream", "error"),
    [
        ([{"t": "restore", "id": 1, "size": 3}], "got 0 bytes in parts, 'size' says 3"),
        (
            [{"t": "part", "of": 1, "data": b"ab"}, {"t": "restore", "id": 1, "size": "2"}],
            "restore: 'size' must be an integer, got '2'",
        ),
        (
            [{"t": "part", "of": 1, "data": b"ab"}, {"t": "restore", "id": 1, "size": -2}],
            "'size' must be a non-negative integer",
        ),
        (
            [{"t": "part", "of": 2, "data": b"ab"}, {"t": "restore", "id": 1, "size": 2}],
            "got 0 bytes",
        ),
        (
            [{"t": "part", "of": 1, "data": b"x" * 60}] * 2
            + [{"t": "restore", "id": 1, "size": 1}],
            "over the limit of 100 bytes",
        ),
    ],
)
def test_parts_that_do_not_add_up_refuse_the_restore(stream: list[object], error: str) -> None:
    decoder = ControlDecoder(max_blob=100)
    (refusal,) = decoder.feed(b"".join(pack(m) for m in stream))
    assert isinstance(refusal, Refusal)
    assert refusal.t == "restore"
    assert error in refusal.error
    # the next transfer starts clean
    more = pack({"t": "part", "of": 9, "data": b"xy"}) + pack({"t": "restore", "id": 9, "size": 2})
    assert decoder.feed(more) == [Request(9, Restore(2), b"xy")]


def test_a_malformed_part_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="'of' must be an integer"):
        ControlDecoder().feed(pack({"t": "part", "of": "x", "data": b""}))
