"""The control channel's pure core: decoding, limits, report builders."""

from __future__ import annotations

import msgpack
import pytest

from sdrpeer.control.parts import parts
from sdrpeer.errors import ProtocolError
from sdrpeer.host import control
from sdrpeer.host.control import Command, ControlDecoder


def pack(value: object) -> bytes:
    return msgpack.packb(value, use_bin_type=True)  # type: ignore[no-any-return]


def test_commands_across_arbitrary_cuts() -> None:
    stream = pack({"t": "activate", "id": 1}) + pack({"t": "exit", "id": 2, "timeout": 1.5})
    for cut in range(len(stream) + 1):
        decoder = ControlDecoder()
        got = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert got == [
            Command("activate", 1, {"t": "activate", "id": 1}),
            Command("exit", 2, {"t": "exit", "id": 2, "timeout": 1.5}),
        ]


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
    assert len(ControlDecoder(max_message=limit).feed(msg)) == 1
    bigger = pack({"t": "set_params", "id": 1, "params": {"blob": blob + b"x" * (pad + 1)}})
    with pytest.raises(ProtocolError, match="limit 1000"):
        ControlDecoder(max_message=limit).feed(bigger)


def test_a_huge_message_fails_before_it_is_buffered() -> None:
    header = b"\xc6" + (50 << 20).to_bytes(4, "big")  # bin32 of 50 MiB
    with pytest.raises(ProtocolError, match="over"):
        ControlDecoder().feed(header + bytes(control.MAX_MESSAGE + 100_000))


def test_many_small_messages_in_one_read_are_fine() -> None:
    stream = b"".join(pack({"t": "activate", "id": i, "pad": "x" * 100}) for i in range(20000))
    assert len(stream) > 2 * control.MAX_MESSAGE
    assert [c.id for c in ControlDecoder().feed(stream)] == list(range(20000))


def test_map_without_integer_id_is_counted_and_skipped() -> None:
    decoder = ControlDecoder()
    stream = pack({"t": "activate"}) + pack({"t": "activate", "id": True})
    assert decoder.feed(stream + pack({"t": "reset", "id": 3})) == [
        Command("reset", 3, {"t": "reset", "id": 3})
    ]
    assert decoder.ignored == 2


def test_report_builders() -> None:
    assert control.state("ERROR", 12.5, "boom") == {
        "t": "state",
        "state": "ERROR",
        "ts": 12.5,
        "error": "boom",
    }
    assert control.reply(4, False, "no") == {"t": "reply", "id": 4, "ok": False, "error": "no"}
    assert control.heartbeat(1.0, {"p": {"frames_in": 1}}) == {
        "t": "heartbeat",
        "ts": 1.0,
        "ports": {"p": {"frames_in": 1}},
    }
    assert control.fault("emergency_stop", "bumper", 3.0) == {
        "t": "fault",
        "kind": "emergency_stop",
        "detail": "bumper",
        "ts": 3.0,
    }
    assert control.state("ERROR", 1.0, "emergency_stop: bumper", "emergency_stop")["fault"] == (
        "emergency_stop"
    )
    assert control.reply(5, True, size=9) == {
        "t": "reply",
        "id": 5,
        "ok": True,
        "error": None,
        "size": 9,
    }
    hello = control.hello(pid=7, component="C", ports={"in": [], "out": []}, params={}, data={})
    assert hello["protocol"] == 1
    assert msgpack.unpackb(control.encode(hello)) == hello


def test_parts_before_a_command_become_its_blob() -> None:
    blob = bytes(range(256)) * 2000  # 512000 bytes: two parts
    stream = b"".join(pack(m) for m in parts(7, blob))
    stream += pack({"t": "restore", "id": 7, "size": len(blob)})
    for cut in (0, 1, 100_000, len(stream) - 1):
        decoder = ControlDecoder()
        got = decoder.feed(stream[:cut]) + decoder.feed(stream[cut:])
        assert [(c.t, c.id, c.blob, c.blob_error) for c in got] == [("restore", 7, blob, None)]


@pytest.mark.parametrize(
    ("stream", "error"),
    [
        ([{"t": "restore", "id": 1, "size": 3}], "got 0 bytes in parts, 'size' says 3"),
        (
            [{"t": "part", "of": 1, "data": b"ab"}, {"t": "restore", "id": 1, "size": "2"}],
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
def test_parts_that_do_not_add_up_are_the_commands_error(stream: list[object], error: str) -> None:
    decoder = ControlDecoder(max_blob=100)
    (command,) = decoder.feed(b"".join(pack(m) for m in stream))
    assert command.blob is None
    assert command.blob_error is not None
    assert error in command.blob_error


def test_a_malformed_part_is_a_protocol_error() -> None:
    with pytest.raises(ProtocolError, match="'of' must be an integer"):
        ControlDecoder().feed(pack({"t": "part", "of": "x", "data": b""}))
