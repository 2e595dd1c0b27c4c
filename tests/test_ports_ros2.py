"""`sdrpeer port record --format ros2` and `replay` of such a file, over a real instance manager
running real hosts (the agent's tap of typed ports, as for the `sdrpeer` format): every message
decodes with rclpy and with rosbags to the value the component sent; a replay delivers the same
values to a typed InPort; an untyped port with `--format ros2` and a file of another kind are
refused, and nothing is written or injected."""

from __future__ import annotations

import asyncio
from pathlib import Path

import msgpack
from mcap.writer import Writer

from sdrpeer.cli.main import main as cli_main
from sdrpeer.ros2.types import MAPPED
from sdrpeer.sdk.robot_types import Odometry, Pose
from tests.ros2_readers import rclpy_messages, rosbags_messages
from tests.test_ports import COUNTER, POSE_KEEPER, POSES, agent, run, spec
from tests.typed_fixture import ODOMETRY
from tests.wait import until_answer, until_async

__all__ = ["agent"]  # the fixture

ODOM = spec("Odom", "tests.typed_fixture:OdomPub", rate=100.0)


def _api(client) -> list[str]:
    return ["--api", str(client.make_url("")).rstrip("/"), "--token", "tok"]


async def test_a_ros2_recording_decodes_with_rclpy_and_rosbags_to_what_was_sent(agent, tmp_path):
    client, manager = agent
    await run(manager, ODOM, POSES)
    out = tmp_path / "odom.mcap"
    argv = ["port", "record", "Odom.odom", "Poses.pose", "--format", "ros2", "-o", str(out)]
    assert await asyncio.to_thread(cli_main, [*argv, "--count", "60", *_api(client)]) == 0
    sent = await manager.snapshot("Odom")
    by_x = {wire[3][2]: ODOMETRY.decode(msgpack.unpackb(msgpack.packb(wire))) for wire in sent}

    by_rclpy = rclpy_messages(out)
    assert len(by_rclpy) == 60
    assert {topic for topic, *_ in by_rclpy} == {"/Odom/odom", "/Poses/pose"}
    odoms = [(pub, m) for topic, pub, m in by_rclpy if topic == "/Odom/odom"]
    assert len(odoms) > 10
    for published, msg in odoms:
        value = MAPPED[Odometry].from_ros(msg)
        assert value == by_x[msg.pose.pose.position.x]  # the very value sent
        assert published == int(value.stamp * 1e9)
    xs = [m.pose.pose.position.x for _, m in odoms]
    assert xs == [xs[0] + i for i in range(len(xs))]  # in order, none missing
    poses = [MAPPED[Pose].from_ros(m) for topic, _, m in by_rclpy if topic == "/Poses/pose"]
    assert all(p.frame == "map" for p in poses)

    by_rosbags = rosbags_messages(out)
    assert [(topic, kind) for topic, kind, _ in by_rosbags if topic == "/Odom/odom"] == [
        ("/Odom/odom", "nav_msgs/msg/Odometry")
    ] * len(odoms)
    got = [MAPPED[Odometry].from_ros(m) for topic, _, m in by_rosbags if topic == "/Odom/odom"]
    assert got == [by_x[x] for x in xs]
    await until_async("the tap's connections removed", lambda: not manager.adhoc_connections())


async def test_a_ros2_recording_replays_the_same_values_into_a_typed_port(agent, tmp_path):
    client, manager = agent
    await run(manager, POSES, POSE_KEEPER)
    out = tmp_path / "poses.mcap"
    argv = ["port", "record", "Poses.pose", "--format", "ros2", "-o", str(out), "--count", "20"]
    assert await asyncio.to_thread(cli_main, [*argv, *_api(client)]) == 0
    recorded = [MAPPED[Pose].from_ros(m) for *_, m in rclpy_messages(out)]
    assert len(recorded) == 20
    argv = ["port", "replay", str(out), "--map", "Poses.pose=PoseKeep.pose", "--speed", "0"]
    assert await asyncio.to_thread(cli_main, [*argv, *_api(client)]) == 0
    kept = await until_answer(
        "20 poses replayed", lambda: manager.snapshot("PoseKeep"), lambda v: len(v) >= 20
    )
    assert kept == [[p.frame, p.x, p.y] for p in recorded]


async def test_an_untyped_port_in_ros2_format_is_refused_and_nothing_is_written(
    agent, tmp_path, capsys
):
    client, manager = agent
    await run(manager, POSES, COUNTER)
    out = tmp_path / "no.mcap"
    argv = ["port", "record", "Poses.pose", "Pub.out", "--format", "ros2", "-o", str(out)]
    rc = await asyncio.to_thread(cli_main, [*argv, "--count", "5", *_api(client)])
    err = capsys.readouterr().err
    assert rc == 1
    assert "Pub.out (untyped) has none" in err
    assert "Pose (geometry_msgs/msg/PoseStamped)" in err
    assert "Poses.pose" not in err.split("has none")[0]  # the mapped port is not blamed
    assert not out.exists()
    await until_async("the tap's connections removed", lambda: not manager.adhoc_connections())


def _foreign(path: Path, encoding: str, schema: str, schema_encoding: str) -> None:
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="", library="test")
        sid = writer.register_schema(schema, schema_encoding, b"string data\n")
        cid = writer.register_channel("Poses.pose", encoding, sid, {"instance": "Poses"})
        for i in range(3):
            writer.add_message(cid, i + 1, b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00", i + 1, i)
        writer.finish()


async def test_a_file_of_another_kind_is_refused_and_nothing_is_injected(agent, tmp_path, capsys):
    client, manager = agent
    await run(manager, POSE_KEEPER)
    cases = {
        "json.mcap": ("json", "Thing", "jsonschema", "is 'json' with schema encoding"),
        "string.mcap": ("cdr", "std_msgs/msg/String", "ros2msg", "which no sdrpeer type maps"),
        "pose.mcap": ("cdr", "geometry_msgs/msg/PoseStamped", "ros2msg", "a message is not a"),
    }
    for name, (encoding, schema, schema_encoding, text) in cases.items():
        path = tmp_path / name
        _foreign(path, encoding, schema, schema_encoding)
        argv = ["port", "replay", str(path), "--map", "Poses.pose=PoseKeep.pose", "--speed", "0"]
        rc = await asyncio.to_thread(cli_main, [*argv, *_api(client)])
        err = capsys.readouterr().err
        assert (rc, text in err, str(path) in err) == (1, True, True), err
    assert await manager.snapshot("PoseKeep") == []
    assert manager.port_counters().get("PoseKeep", {}).get("pose", {}).get("frames_in", 0) == 0
