"""The control codec: every message encodes to exactly the bytes the hand-built maps had (so an
old host and a new agent still speak), decodes back to itself, and a wrong field is named."""

from __future__ import annotations

from typing import Any

import msgpack
import pytest

from sdrpeer.control.codec import decode_command, decode_part, decode_report, encode, to_map
from sdrpeer.control.messages import (
    COMMANDS,
    REPORTS,
    Activate,
    Command,
    Conn,
    Connect,
    DataKeys,
    Deactivate,
    Disconnect,
    Exit,
    Fault,
    Heartbeat,
    Hello,
    Part,
    Refused,
    Reply,
    Repoint,
    Report,
    Reset,
    Restore,
    SetParams,
    Snapshot,
    State,
    Step,
)
from sdrpeer.errors import ProtocolError


def packed(value: dict[str, Any]) -> bytes:
    """How both ends packed a map before the codec (sdrpeer/control/stream.py: encode)."""
    return bytes(msgpack.packb(dict(value), use_bin_type=True))


# The maps as the code before the codec built them: the host's report builders
# (sdrpeer/host/control.py) and the agent's `{"t": t, "id": cid, **fields}` with the fields its
# callers passed (runtime/manager.py, runtime/supervisor.py, runtime/handoff.py, profiling).


def legacy_hello(**kw: Any) -> dict[str, Any]:
    return {"t": "hello", "protocol": 1, **kw}


def legacy_state(name: str, now: float, error: str | None = None, fault: str | None = None):
    msg: dict[str, Any] = {"t": "state", "state": name, "ts": now, "error": error}
    if fault is not None:
        msg["fault"] = fault
    return msg


def legacy_reply(ident: int, ok: bool, error: str | None = None, size: int | None = None):
    msg: dict[str, Any] = {"t": "reply", "id": ident, "ok": ok, "error": error}
    if size is not None:
        msg["size"] = size
    return msg


def legacy_command(t: str, cid: int, **fields: Any) -> dict[str, Any]:
    return {"t": t, "id": cid, **fields}


HELLO: dict[str, Any] = {
    "pid": 4242,
    "component": "Camera",
    "ports": {"in": ["trigger"], "out": ["image", "info"]},
    "params": {"rate": 5.0, "mode": "fast", "n": 3, "on": True},
    "data": {"tcp": "10.0.0.7:40123", "unix": "/run/sdrpeer/c.sock"},
}
WIRE = {"id": "c1", "out": "image", "to": "tcp://10.0.0.8:4000", "in": "image"}
POLICY = {"push": "fifo", "buffer": 64, "full": "block", "skip": 0}
KEYS = ["00" * 32, "ff" * 16]
COUNTERS = {"frames_out": 10, "bytes_out": 800, "dropped": 0}

SERVICES = {
    "planner": {"role": "provides", "interface": "demo/Planner#0a1b2c3d", "methods": ["compute"]},
    "map": {"role": "requires", "interface": "demo/Map#00ff00ff", "methods": ["get", "put"]},
}

REPORT_CASES: list[tuple[Report | Part, dict[str, Any]]] = [
    (Hello(**HELLO), legacy_hello(**HELLO)),
    (Hello(**HELLO, services=SERVICES), legacy_hello(**HELLO, services=SERVICES)),
    (State("INACTIVE", 1795000000.25), legacy_state("INACTIVE", 1795000000.25)),
    (State("ERROR", 12.5, "boom"), legacy_state("ERROR", 12.5, "boom")),
    (
        State("ERROR", 1.0, "emergency_stop: bumper", "emergency_stop"),
        legacy_state("ERROR", 1.0, "emergency_stop: bumper", "emergency_stop"),
    ),
    (Reply(4, False, "no"), legacy_reply(4, False, "no")),
    (Reply(5, True), legacy_reply(5, True)),
    (Reply(6, True, size=9), legacy_reply(6, True, size=9)),
    (
        Heartbeat(1.5, {"image": COUNTERS}),
        {"t": "heartbeat", "ts": 1.5, "ports": {"image": COUNTERS}},
    ),
    (
        Heartbeat(1.5, {"image": COUNTERS}, {"accepted": 2, "refused_auth": 1}),
        {
            "t": "heartbeat",
            "ts": 1.5,
            "ports": {"image": COUNTERS},
            "data": {"accepted": 2, "refused_auth": 1},
        },
    ),
    (
        Fault("emergency_stop", "bumper", 3.0),
        {"t": "fault", "kind": "emergency_stop", "detail": "bumper", "ts": 3.0},
    ),
    (
        Refused("c1", "Cam.image", "tcp://10.0.0.8:4000", "image", "unknown in-port", 2, 3.0),
        {
            "t": "refused",
            "conn": "c1",
            "from": "Cam.image",
            "to": "tcp://10.0.0.8:4000",
            "in": "image",
            "error": "unknown in-port",
            "count": 2,
            "ts": 3.0,
        },
    ),
    (
        Refused("c1", "Cam.image", "tcp://10.0.0.8:4000", "image", None, 0, 4.0),
        {
            "t": "refused",
            "conn": "c1",
            "from": "Cam.image",
            "to": "tcp://10.0.0.8:4000",
            "in": "image",
            "error": None,
            "count": 0,
            "ts": 4.0,
        },
    ),
    (Part(7, b"\x00\x01" * 10), {"t": "part", "of": 7, "data": b"\x00\x01" * 10}),
]

COMMAND_CASES: list[tuple[Command, dict[str, Any]]] = [
    (Activate(), legacy_command("activate", 1)),
    (Deactivate(), legacy_command("deactivate", 2)),
    (Reset(), legacy_command("reset", 3)),
    (SetParams({"gain": 7.5, "mode": "slow"}), legacy_command("set_params", 4, params={
        "gain": 7.5, "mode": "slow"})),
    (
        Connect(Conn("c1", "image", "tcp://10.0.0.8:4000", "image", POLICY)),
        legacy_command("connect", 5, conn={**WIRE, "policy": POLICY}),
    ),
    (
        Connect(Conn("c1", "image", "tcp://10.0.0.8:4000", "image", {})),
        legacy_command("connect", 6, conn={**WIRE, "policy": {}}),
    ),
    (Disconnect("c1"), legacy_command("disconnect", 7, conn_id="c1")),
    (Repoint("c1", "unix:///run/x.sock"), legacy_command("repoint", 8, conn_id="c1",
                                                         to="unix:///run/x.sock")),
    (DataKeys(tuple(KEYS)), legacy_command("data_keys", 9, keys=KEYS)),
    (Exit(5.0), legacy_command("exit", 10, timeout=5.0)),
    (Exit(), legacy_command("exit", 11)),
    (Snapshot(16 << 20), legacy_command("snapshot", 12, max=16 << 20)),
    (Restore(300_000), legacy_command("restore", 13, size=300_000)),
    (Step(3), legacy_command("step", 14, n=3)),
]  # fmt: skip


@pytest.mark.parametrize(("msg", "legacy"), REPORT_CASES)
def test_a_report_is_the_bytes_it_always_was(msg: Report | Part, legacy: dict[str, Any]) -> None:
    assert encode(msg) == packed(legacy)
    decoded = decode_part(legacy) if isinstance(msg, Part) else decode_report(legacy)
    assert decoded == msg


@pytest.mark.parametrize(("msg", "legacy"), COMMAND_CASES)
def test_a_command_is_the_bytes_it_always_was(msg: Command, legacy: dict[str, Any]) -> None:
    assert encode(msg, legacy["id"]) == packed(legacy)
    assert decode_command(legacy) == msg


def test_every_message_class_has_a_case() -> None:
    covered = {type(m) for m, _ in REPORT_CASES + COMMAND_CASES}
    assert covered == {*COMMANDS, *REPORTS, Part}


def test_a_command_needs_an_id_and_a_report_has_none() -> None:
    with pytest.raises(ValueError, match="activate: a command needs an id"):
        to_map(Activate())
    assert "id" not in to_map(State("ACTIVE", 1.0))


def test_what_a_foreign_peer_may_leave_out_or_add() -> None:
    # unknown keys are ignored; optional fields get their defaults; integer times are floats
    raw = {"t": "state", "state": "ACTIVE", "ts": 3, "extra": [1]}
    assert decode_report(raw) == State("ACTIVE", 3.0)
    assert decode_report({"t": "fault", "kind": "k", "detail": "d"}) == Fault("k", "d", None)
    assert decode_report({"t": "mystery"}) is None
    assert decode_command({"t": "connect", "id": 1, "conn": WIRE}) == Connect(
        Conn("c1", "image", "tcp://10.0.0.8:4000", "image")
    )
    assert decode_command({"t": "exit", "id": 1, "timeout": 2}) == Exit(2.0)


@pytest.mark.parametrize(
    ("raw", "error"),
    [
        ({"t": "hello", **HELLO, "ports": {"in": "x"}}, "hello: 'ports' must be a map of string"),
        ({"t": "hello", **HELLO, "data": {"tcp": 1}}, "hello: 'data' must be a map of strings"),
        ({"t": "hello", **HELLO, "component": None}, "hello: 'component' must be a string"),
        (
            {"t": "hello", **HELLO, "services": {"p": {**SERVICES["map"], "role": "serves"}}},
            "hello: 'services' must be a map of service maps",
        ),
        (
            {"t": "hello", **HELLO, "services": {"p": {**SERVICES["map"], "methods": [1]}}},
            "hello: 'services' must be a map of service maps",
        ),
        (
            {"t": "hello", **HELLO, "services": {"p": {"role": "provides", "interface": "i"}}},
            "hello: 'services' must be a map of service maps",
        ),
        ({"t": "reply", "id": 1, "ok": 1}, "reply: 'ok' must be a boolean, got 1"),
        ({"t": "reply", "id": 1, "ok": True, "size": "9"}, "reply: 'size' must be an integer"),
        ({"t": "part", "of": 1, "data": "text"}, "part: 'data' must be bytes"),
        ({"t": "state", "state": "ERROR", "ts": 1.0, "error": 5}, "state: 'error' must be a"),
        ({"t": "heartbeat", "ts": 1.0}, "heartbeat: no 'ports'"),
        ({"t": "fault", "kind": "k", "detail": "x" * 500}, None),
    ],
)
def test_a_wrong_field_is_named(raw: dict[str, Any], error: str | None) -> None:
    if error is None:  # a long value is fine, and a long error value is cut in the message
        assert decode_report(raw) is not None
        with pytest.raises(ProtocolError, match=r"'kind' must be a string, got 1{57}\.\.\.$"):
            decode_report({**raw, "kind": int("1" * 80)})
        return
    with pytest.raises(ProtocolError, match=error):
        decode_report(raw)
