"""Typed ports: message types and their ids, the wire form (arrays; a big image's blob without a
copy), typed OutPorts and InPorts, the data stream refusing a sender of another type, and
`system check` refusing a connection between ports of different types."""

from __future__ import annotations

import asyncio
from dataclasses import dataclass
from pathlib import Path

import msgpack
import pytest

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.errors import SdrpeerError
from sdrpeer.sdk import (
    BatteryState,
    Image,
    InPort,
    Odometry,
    OutPort,
    PortTypeError,
    Pose,
    RangeScan,
    Velocity,
    message,
)
from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.ports import OutPortRuntime
from sdrpeer.sdk.typed import BLOB_MIN, WireBlob, message_type
from sdrpeer.system.loader import parse_system
from tests.realnet import RealCluster
from tests.test_recovery_e2e import deploy
from tests.wait import until_async

ODOM = Odometry(1.5, "odom", "base", Pose(1.5, "odom", 1.0, 2.0), Velocity(1.5, "base", 0.5))


def wire(value: object) -> object:
    """What a typed OutPort sends, as the receiver unpacks it."""
    info = message_type(type(value))
    assert info is not None
    encoded = info.encode(value)
    if isinstance(encoded, WireBlob):
        return msgpack.unpackb(encoded.prefix + encoded.data)
    return msgpack.unpackb(msgpack.packb(encoded))


@pytest.mark.parametrize(
    "value",
    [
        Pose(1.0, "map", 1.0, 2.0, 0.0, 0.0, 0.0, 0.38, 0.92),
        Velocity(2.0, "base", 0.5, wz=0.1),
        ODOM,
        RangeScan(3.0, "laser", -1.5, 0.01, 0.1, 30.0, [1.0, 2.5, 31.0]),
        Image(4.0, "cam", 2, 1, "mono8", 2, b"\x00\xff"),
        Image(4.0, "cam", 640, 480, "rgb8", 1920, bytes(640 * 480 * 3)),  # a blob
        BatteryState(5.0, 24.1, -1.2, 87.5, False),
    ],
)
def test_every_standard_type_round_trips(value: object) -> None:
    info = message_type(type(value))
    assert info is not None
    assert info.decode(wire(value)) == value


def test_a_big_image_travels_as_a_blob_and_a_small_one_as_an_array() -> None:
    info = message_type(Image)
    assert info is not None
    data = bytes(range(256)) * (BLOB_MIN // 256)
    big = info.encode(Image(1.0, "cam", 256, BLOB_MIN // 256, "mono8", 256, data))
    assert isinstance(big, WireBlob)
    assert big.data is data  # not copied
    assert isinstance(info.encode(Image(1.0, "cam", 1, 1, "mono8", 1, b"x")), tuple)


def test_type_ids_tell_layouts_apart() -> None:
    @message("lab/Detection")
    @dataclass
    class One:
        stamp: float
        label: str

    @message("lab/Detection")
    @dataclass
    class Two:
        stamp: float
        score: float

    one, two = message_type(One), message_type(Two)
    assert one is not None
    assert two is not None
    assert one.type_id.startswith("lab/Detection#")
    assert one.type_id != two.type_id  # same name, another layout
    assert message_type(Pose).type_id == "sdrpeer/Pose#4a699e8d"  # type: ignore[union-attr]
    with pytest.raises(TypeError, match="a message field must be"):

        @message("lab/Bad")
        @dataclass
        class Bad:
            when: complex


def test_typed_ports_check_what_is_written_and_decode_what_is_read() -> None:
    out = OutPortRuntime("pose", port_type=Pose)
    sent: list[object] = []

    class Sink:
        def offer(self, value: object) -> bool:
            sent.append(value)
            return True

    out.attach(Sink())
    out.write(Pose(1.0, "map", 3.0, 4.0))
    with pytest.raises(PortTypeError, match="sends sdrpeer/Pose"):
        out.write({"x": 3.0})
    assert sent == [(1.0, "map", 3.0, 4.0, 0.0, 0.0, 0.0, 0.0, 1.0)]
    port = InPortRuntime("pose", port_type=Pose)
    port.deliver(msgpack.unpackb(msgpack.packb(sent[0])), 1, "c")
    port.deliver(msgpack.unpackb(msgpack.packb(sent[0])), 2, "c")
    assert port.get_nowait() == Pose(1.0, "map", 3.0, 4.0)
    newest = port.read()
    assert newest == Pose(1.0, "map", 3.0, 4.0)
    assert port.read() is newest  # decoded once
    port.deliver(42, 3, "c")  # an untyped sender's value: refused and counted, never queued
    assert (port.refused, port.qsize()) == (1, 0)
    assert port.read() is newest


def test_a_nested_type_is_read_after_it_was_taken() -> None:
    """get_nowait() then read() decode the same received list: decoding must not change it."""
    info = message_type(Odometry)
    assert info is not None
    port = InPortRuntime("odom", port_type=Odometry)
    port.deliver(msgpack.unpackb(msgpack.packb(info.encode(ODOM))), 1, "c")
    assert port.get_nowait() == ODOM
    assert port.read() == ODOM


async def stream(
    tmp_path: Path, sends: type | None, takes: type | None, kind: str = "tcp"
) -> tuple[Connection, DataServer, InPortRuntime]:
    port = InPortRuntime("in", port_type=takes)
    server = DataServer(lambda name: port if name == "in" else None, unix_path=str(tmp_path / "s"))
    await server.start()
    info = None if sends is None else message_type(sends)
    conn = Connection(
        "c",
        f"{kind}://{server.addresses[kind]}",
        "in",
        "pub.out",
        InPort().policy,
        type_id=None if info is None else info.type_id,
    )
    conn.start()
    return conn, server, port


@pytest.mark.parametrize("kind", ["tcp", "unix"])  # unix: the blob goes through the shm ring
async def test_typed_values_cross_a_real_stream(tmp_path: Path, kind: str) -> None:
    conn, server, port = await stream(tmp_path, Image, Image, kind)
    info = message_type(Image)
    assert info is not None
    big = Image(1.0, "cam", 640, 480, "rgb8", 1920, bytes(range(256)) * 3600)
    try:
        await until_async("connected", lambda: conn.connected, bool)
        assert conn.offer(info.encode(big))
        got = await asyncio.wait_for(port.get(), 10)
        assert got == big
    finally:
        await conn.close()
        await server.close()


async def test_a_sender_of_another_type_is_refused(tmp_path: Path) -> None:
    conn, server, port = await stream(tmp_path, Pose, Image)
    try:
        await until_async(
            "the refusal", lambda: conn.last_error or "", lambda e: "type mismatch" in e
        )
        assert "pub.out sends sdrpeer/Pose#" in str(conn.last_error)
        assert "in takes sdrpeer/Image#" in str(conn.last_error)
        assert server.counters["refused_type"] >= 1
        assert not conn.connected
        assert port.frames_in == 0
    finally:
        await conn.close()
        await server.close()


def system(to: str) -> str:
    return (
        "name: typed\ncomponents:\n"
        "  - {name: Pub, target: 'tests.typed_fixture:PosePub'}\n"
        "  - {name: Rec, target: 'tests.typed_fixture:PoseRec'}\n"
        "  - {name: Img, target: 'tests.typed_fixture:ImageRec'}\n"
        f"connections:\n  - {{from: Pub.pose, to: {to}}}\n"
    )


def test_system_check_refuses_ports_of_different_types() -> None:
    assert parse_system(system("Rec.pose"), "typed.yaml").connections  # same type: fine
    with pytest.raises(SdrpeerError) as e:
        parse_system(system("Img.image"), "typed.yaml")
    message_text = str(e.value)
    assert "typed.yaml:7" in message_text
    assert "Pub.pose sends sdrpeer/Pose#4a699e8d but Img.image takes sdrpeer/Image#" in message_text


def test_untyped_and_typed_ports_connect() -> None:
    """An end that declares no type takes or sends any value (the host checks nothing)."""
    text = system("Rec.pose").replace("PoseRec", "ImageRec").replace("Rec.pose", "Img.image")
    text = text.replace("tests.typed_fixture:PosePub", "tests.components_fixture:Counter")
    text = text.replace("Pub.pose", "Pub.out")
    assert parse_system(text, "typed.yaml").connections
    assert OutPort().type_id is None


@pytest.mark.realnet
def test_typed_components_on_a_real_agent(cluster: RealCluster, tmp_path: Path) -> None:
    """PosePub -> PoseRec deployed from a system file: Poses flow between two real hosts."""
    agent = cluster.start("robot-1")
    path = tmp_path / "typed.yaml"
    path.write_text(
        system("Rec.pose").replace("  - {name: Img, target: 'tests.typed_fixture:ImageRec'}\n", "")
    )
    deploy(cluster, agent, path)
    cluster.wait_until(
        lambda: next(r for r in agent.get("/v1/instances") if r["component"] == "Rec")["ports"],
        lambda ports: ports.get("pose", {}).get("frames_in", 0) > 20,
        "poses into Rec",
    )
