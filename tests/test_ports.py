"""The port tools (sdrpeer.ports, `sdrpeer port ...`) over a real instance manager running real
hosts, with data keys (every stream the agent opens is authenticated): list, run-time connect and
disconnect, print (a tap), inject (typed values checked), record a camera to MCAP and replay it
frame-exact; refusals (unknown port or instance, type mismatch, wrong direction, no token)."""

from __future__ import annotations

import asyncio
import io
import json
import os
import time
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import msgpack
import pytest
from aiohttp.test_utils import TestClient, TestServer
from mcap.reader import make_reader

from sdrpeer.api.app import build_app
from sdrpeer.cli.main import main as cli_main
from sdrpeer.ports.mcapfile import read_recording
from sdrpeer.ports.routes import ROUTES
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.sdk.robot_types import Pose
from sdrpeer.sdk.typed import type_id_of
from tests.wait import until_answer, until_async

TOKEN = "tok"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
POSE = type_id_of(Pose)


class View:
    """Just enough of an agent: a name, an instance manager, one other robot's record."""

    def __init__(self, manager: InstanceManager) -> None:
        self.instances = manager
        self.name = "robot-1"

    def members_view(self) -> list[dict[str, Any]]:
        return [
            {"name": "robot-1", "instances": []},
            {"name": "robot-2", "api": "http://127.0.0.2:9", "instances": [{"name": "Far"}]},
        ]

    def agent_view(self) -> dict[str, Any]:
        return {}

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        return []

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        return {}


def spec(name: str, target: str, **params: Any) -> InstanceSpec:
    return InstanceSpec.from_json({"name": name, "target": target, "params": params})


CAM = spec("Cam", "components.camera:Camera", rate=50.0, width=32, height=24)
COUNTER = spec("Pub", "tests.components_fixture:Counter", rate=200.0)
KEEPER = spec("Keep", "tests.port_fixture:Keeper")
POSES = spec("Poses", "tests.typed_fixture:PosePub", rate=100.0)
POSE_KEEPER = spec("PoseKeep", "tests.port_fixture:PoseKeeper")
IMAGES = spec("Images", "tests.typed_fixture:ImageRec")
SLOW = spec("Slow", "tests.port_fixture:SlowKeeper")
MONO = spec("Mono", "tests.port_fixture:MonoCamera")
IMAGE_KEEPER = spec("ImageKeep", "tests.port_fixture:ImageKeeper")


@pytest.fixture
async def agent(tmp_path: Path) -> AsyncIterator[tuple[TestClient[Any, Any], InstanceManager]]:
    manager = InstanceManager(tmp_path, supervisor_fast(), interval=0.1)
    manager.data_keys = (os.urandom(32),)
    await manager.start()
    client = TestClient(TestServer(build_app(View(manager), token=TOKEN, extra_routes=ROUTES)))
    await client.start_server()
    try:
        yield client, manager
    finally:
        await client.close()
        async with asyncio.timeout(15):
            await manager.stop()


async def run(manager: InstanceManager, *specs: InstanceSpec) -> None:
    manager.set_desired(specs)
    names = {s.name for s in specs}
    await until_async(
        f"{sorted(names)} ACTIVE",
        lambda: {s["name"]: s["state"] for s in manager.status() if s["name"] in names},
        lambda states: set(states.values()) == {"ACTIVE"} and len(states) == len(names),
        within=20,
    )


def counter(manager: InstanceManager, name: str, port: str, key: str) -> int:
    return int(manager.port_counters().get(name, {}).get(port, {}).get(key, 0))


async def post(client: TestClient[Any, Any], path: str, body: Any) -> tuple[int, Any]:
    resp = await client.post(path, json=body, headers=AUTH)
    return resp.status, await resp.json()


async def test_list_shows_directions_types_and_connections(agent):
    client, manager = agent
    keeper = InstanceSpec.from_json(
        {**COUNTER.to_json(), "connections": [{"out": "out", "to": "Keep", "in": "inp"}]}
    )
    await run(manager, keeper, KEEPER, POSES)
    await until_async("Pub connected", lambda: manager.made_connections("Pub"))
    resp = await client.get("/v1/ports")
    assert resp.status == 200
    rows = {f"{r['instance']}.{r['port']}": r for r in await resp.json()}
    assert set(rows) == {"Pub.out", "Keep.inp", "Poses.pose"}
    assert rows["Pub.out"]["direction"] == "out"
    assert rows["Pub.out"]["type"] is None
    assert [c["to"] for c in rows["Pub.out"]["connections"]] == ["Keep.inp"]
    assert [c["from"] for c in rows["Keep.inp"]["connections"]] == ["Pub.out"]
    assert rows["Keep.inp"]["direction"] == "in"
    assert rows["Poses.pose"]["type"] == POSE


async def test_connect_carries_data_survives_a_new_spec_and_disconnect_stops_it(agent):
    client, manager = agent
    await run(manager, COUNTER, KEEPER)
    status, body = await post(client, "/v1/ports/connect", {"from": "Pub.out", "to": "Keep.inp"})
    assert status == 200, body
    cid = body["id"]
    first = await until_async(
        "frames at Keep", lambda: counter(manager, "Keep", "inp", "frames_in"), lambda n: n > 0
    )
    manager.set_desired([COUNTER])  # a new plan for the sender: the run-time connection stays
    await until_async(
        "more frames at Keep",
        lambda: counter(manager, "Keep", "inp", "frames_in"),
        lambda n: n > first + 20,
    )
    assert cid in manager.made_connections("Pub")
    status, body = await post(client, "/v1/ports/disconnect", {"id": cid})
    assert (status, body) == (200, {"removed": cid})
    await until_async("connection gone", lambda: cid not in manager.made_connections("Pub"))

    # counters come with heartbeats (0.5 s apart): the flow has stopped once Keep's count
    # holds while Pub writes 300 more frames (1.5 s: Keep beats at least twice); a few tries
    # allow for frames still on their way
    def pub_out() -> int:
        return counter(manager, "Pub", "out", "frames_out")

    held = False
    for _ in range(5):
        before = counter(manager, "Keep", "inp", "frames_in")
        target = pub_out() + 300
        await until_async("Pub writes 300 more", pub_out, lambda n: n > target)  # noqa: B023
        if counter(manager, "Keep", "inp", "frames_in") == before:
            held = True
            break
    assert held, "frames still reach Keep after the disconnect"
    status, _ = await post(client, "/v1/ports/disconnect", {"id": cid})
    assert status == 404


async def test_a_run_time_connection_goes_when_its_receiver_stops(agent):
    client, manager = agent
    await run(manager, COUNTER, KEEPER)
    status, _ = await post(client, "/v1/ports/connect", {"from": "Pub.out", "to": "Keep.inp"})
    assert status == 200
    await until_async("connected", lambda: manager.made_connections("Pub"))
    manager.remove("Keep")
    assert manager.adhoc_connections() == []
    await until_async("disconnected", lambda: not manager.made_connections("Pub"))


async def test_refusals(agent):
    client, manager = agent
    await run(manager, POSES, IMAGES, KEEPER)
    resp = await client.post("/v1/ports/connect", json={"from": "Poses.pose", "to": "Keep.inp"})
    assert resp.status == 401
    resp = await client.post("/v1/ports/tap", json={"ports": ["Poses.pose"], "count": 1})
    assert resp.status == 401
    resp = await client.post("/v1/ports/inject", json={"port": "Keep.inp", "value": 1})
    assert resp.status == 401
    resp = await client.post("/v1/ports/feed?port=Keep.inp", data=msgpack.packb([0, 1]))
    assert resp.status == 401
    cases = [
        ({"from": "Poses.pose", "to": "Images.image"}, 409, "type mismatch"),
        ({"from": "Poses.nope", "to": "Keep.inp"}, 404, "no port 'nope'"),
        ({"from": "Ghost.out", "to": "Keep.inp"}, 404, "no instance 'Ghost'"),
        ({"from": "Far.out", "to": "Keep.inp"}, 404, "are on robot-2, not robot-1: ask it"),
        ({"from": "Keep.inp", "to": "Images.image"}, 409, "not an out-port"),
        ({"from": "Poses.pose", "to": "Poses.pose"}, 409, "not an in-port"),
        ({"from": "Poses", "to": "Keep.inp"}, 400, "expected Instance.port"),
    ]
    for body, code, text in cases:
        status, answer = await post(client, "/v1/ports/connect", body)
        assert (status, text in answer["error"]) == (code, True), (body, answer)
    assert manager.adhoc_connections() == []


async def test_print_streams_n_typed_frames_as_field_maps(agent):
    client, manager = agent
    await run(manager, POSES)
    resp = await client.post(
        "/v1/ports/tap", json={"ports": ["Poses.pose"], "count": 5, "decode": True}, headers=AUTH
    )
    assert resp.status == 200
    items = list(msgpack.Unpacker(io.BytesIO(await resp.read()), raw=False))
    header, frames, end = items[0], items[1:-1], items[-1]
    assert header["ports"][0]["type"] == POSE
    assert header["ports"][0]["fields"][:3] == [
        ["stamp", "float"],
        ["frame", "str"],
        ["x", "float"],
    ]
    assert len(frames) == 5
    xs = [value["x"] for _, _, _, value in frames]
    assert all(value["frame"] == "map" for _, _, _, value in frames)
    assert xs == sorted(xs)
    assert len(set(xs)) == 5
    assert (end["end"], end["frames"]) == ("count", 5)
    await until_async("the tap's connection removed", lambda: not manager.adhoc_connections())
    await until_async("and unmade", lambda: not manager.made_connections("Poses"))


async def test_inject_checks_a_typed_value_and_the_port_takes_it(agent):
    client, manager = agent
    await run(manager, POSE_KEEPER)
    value = {"stamp": 1.5, "frame": "odom", "x": 3, "y": -1.25}
    status, body = await post(
        client, "/v1/ports/inject", {"port": "PoseKeep.pose", "value": value, "count": 3}
    )
    assert (status, body) == (200, {"port": "PoseKeep.pose", "sent": 3})
    poses = await until_answer(
        "3 poses taken", lambda: manager.snapshot("PoseKeep"), lambda p: len(p) >= 3
    )
    assert poses == [["odom", 3.0, -1.25]] * 3
    bad = [
        ({**value, "x": "a"}, "value.x: expected a float, got 'a'"),
        ({**value, "z2": 1}, "value.z2: sdrpeer/Pose#"),
        ({"x": 1.0}, "value.stamp: missing"),
        ([1, 2], "is a map of its fields"),
    ]
    for given, text in bad:
        status, body = await post(
            client, "/v1/ports/inject", {"port": "PoseKeep.pose", "value": given}
        )
        assert (status, text in body["error"]) == (400, True), body
    assert len(await manager.snapshot("PoseKeep")) == 3


async def test_a_camera_recorded_to_mcap_replays_frame_exact(agent, tmp_path):
    client, manager = agent
    await run(manager, CAM, KEEPER)
    api = ["--api", str(client.make_url("")).rstrip("/"), "--token", TOKEN]
    out = tmp_path / "cam.mcap"
    rc = await asyncio.to_thread(
        cli_main, ["port", "record", "Cam.image", "-o", str(out), "--count", "20", *api]
    )
    assert rc == 0
    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        [channel] = summary.channels.values()
        schema = summary.schemas[channel.schema_id]
        messages = [
            (m.log_time, m.publish_time, m.sequence, m.data)
            for _, _, m in reader.iter_messages(log_time_order=False)
        ]
    assert (channel.topic, channel.message_encoding) == ("Cam.image", "msgpack")
    assert (channel.metadata["instance"], channel.metadata["port"]) == ("Cam", "image")
    assert (schema.name, schema.encoding) == ("sdrpeer/any", "jsonschema")
    assert len(messages) == 20
    frames = [msgpack.unpackb(data, raw=False) for *_, data in messages]
    assert [f["seq"] for f in frames] == list(range(frames[0]["seq"], frames[0]["seq"] + 20))
    assert all(len(f["pixels"]) == 32 * 24 and isinstance(f["pixels"], bytes) for f in frames)
    published = [pub for _, pub, _, _ in messages]
    assert published == [int(f["ts"] * 1e9) for f in frames]  # the frame's own time
    logs = [log for log, *_ in messages]
    assert logs == sorted(logs)

    start = time.monotonic()
    rc = await asyncio.to_thread(
        cli_main, ["port", "replay", str(out), "--map", "Cam.image=Keep.inp", "--speed", "4", *api]
    )
    took = time.monotonic() - start
    assert rc == 0
    assert took >= (logs[-1] - logs[0]) / 1e9 / 4 * 0.9  # paced, not all at once
    kept = await until_answer(
        "20 frames replayed", lambda: manager.snapshot("Keep"), lambda v: len(v) >= 20
    )
    assert [msgpack.packb(v) for v in kept] == [data for *_, data in messages]


async def test_replay_refuses_a_port_it_cannot_feed(agent, tmp_path, capsys):
    client, manager = agent
    await run(manager, POSES, IMAGES)
    api = ["--api", str(client.make_url("")).rstrip("/"), "--token", TOKEN]
    out = tmp_path / "poses.mcap"
    rc = await asyncio.to_thread(
        cli_main, ["port", "record", "Poses.pose", "-o", str(out), "--count", "3", *api]
    )
    assert rc == 0
    with out.open("rb") as f:  # a typed port's channel: its type and fields in the schema
        [(schema, channel, message), *_] = make_reader(f).iter_messages()
    assert schema is not None
    assert (schema.name, schema.encoding, channel.metadata["type"]) == (POSE, "jsonschema", POSE)
    doc = json.loads(schema.data)
    assert doc["x-sdrpeer-fields"][:3] == [["stamp", "float"], ["frame", "str"], ["x", "float"]]
    assert [i["title"] for i in doc["prefixItems"]][:3] == ["stamp", "frame", "x"]
    wire = msgpack.unpackb(message.data)
    assert (len(wire), wire[1]) == (9, "map")  # the array of its fields, as on the wire
    assert message.publish_time == int(wire[0] * 1e9)  # its stamp
    capsys.readouterr()
    rc = await asyncio.to_thread(cli_main, ["port", "replay", str(out), *api])
    assert (rc, "connected to no InPort" in capsys.readouterr().err) == (1, True)
    mapped = ["--map", "Poses.pose=Images.image"]
    rc = await asyncio.to_thread(cli_main, ["port", "replay", str(out), *mapped, *api])
    err = capsys.readouterr().err
    assert (rc, f"are {POSE}, it takes sdrpeer/Image#" in err) == (1, True), err
    rc = await asyncio.to_thread(cli_main, ["port", "replay", str(out), "--map", "X.y=Z.w", *api])
    assert (rc, "X.y not in" in capsys.readouterr().err) == (2, True)


async def test_a_tap_whose_client_leaves_takes_its_connection_away(agent):
    client, manager = agent
    await run(manager, COUNTER)
    resp = await client.post("/v1/ports/tap", json={"ports": ["Pub.out"]}, headers=AUTH)
    assert resp.status == 200
    assert await resp.content.readany()  # the header, at least
    await until_async("the tap connected", lambda: manager.made_connections("Pub"))
    resp.close()
    await until_async("the tap's connection removed", lambda: not manager.adhoc_connections())
    await until_async("and unmade", lambda: not manager.made_connections("Pub"))


async def test_the_cli_connects_lists_prints_injects_and_disconnects(agent, capsys):
    client, manager = agent
    await run(manager, COUNTER, KEEPER, POSES, POSE_KEEPER)
    api = ["--api", str(client.make_url("")).rstrip("/"), "--token", TOKEN]

    async def cli(*argv: str) -> int:
        return await asyncio.to_thread(cli_main, [*argv, *api])

    assert await cli("port", "connect", "Pub.out", "Keep.inp", "--policy", "buffer=64") == 0
    await until_async("frames at Keep", lambda: counter(manager, "Keep", "inp", "frames_in"))
    await until_async("Pub's rates", lambda: manager.port_rates().get("Pub", {}).get("out"))
    capsys.readouterr()
    assert await cli("port", "list", "--here") == 0
    rows = {line.split()[1]: line.split() for line in capsys.readouterr().out.splitlines()[1:-1]}
    assert rows["Pub.out"][2:4] == ["out", "-"]
    assert rows["Pub.out"][-1] == "+Keep.inp"  # a run-time connection
    assert float(rows["Pub.out"][5]) > 0  # frames/s
    assert rows["Keep.inp"][-1] == "+Pub.out"
    assert rows["Poses.pose"][3] == POSE
    assert await cli("port", "print", "Poses.pose", "--count", "3") == 0
    printed = [json.loads(line) for line in capsys.readouterr().out.splitlines()]
    assert [p["value"]["frame"] for p in printed] == ["map"] * 3
    value = "{stamp: 2, frame: base, x: 1, y: 2}"
    assert await cli("port", "inject", "PoseKeep.pose", value, "--count", "2", "--rate", "50") == 0
    poses = await until_answer(
        "2 poses taken", lambda: manager.snapshot("PoseKeep"), lambda p: len(p) >= 2
    )
    assert poses == [["base", 1.0, 2.0]] * 2
    assert await cli("port", "inject", "PoseKeep.pose", "{stamp: 2, frame: b, x: a, y: 2}") == 1
    assert "value.x: expected a float" in capsys.readouterr().err
    assert await cli("port", "disconnect", "Pub.out", "Keep.inp") == 0
    assert manager.adhoc_connections() == []


async def test_a_feed_into_a_slow_consumer_loses_nothing_and_keeps_the_order(agent):
    client, manager = agent
    await run(manager, SLOW)
    body = b"".join(msgpack.packb([0, n]) for n in range(60))
    resp = await client.post("/v1/ports/feed?port=Slow.inp", data=body, headers=AUTH)
    assert (resp.status, await resp.json()) == (200, {"frames": 60, "sent": {"Slow.inp": 60}})
    taken = await until_answer(
        "60 values taken", lambda: manager.snapshot("Slow"), lambda v: len(v) >= 60
    )
    assert taken == list(range(60))  # its own buffer of 8 overwrites; the feed's blocks instead
    bad = [
        (b"\x93\x01", "frame 1: the body ends inside it"),
        (msgpack.packb(7), "frame 1: expected [index, value]"),
        (msgpack.packb([0, 1]) + msgpack.packb([3, 1]), "frame 2: no port at index 3"),
        (b"\xc1", "frame 1: not msgpack"),
    ]
    for data, text in bad:
        resp = await client.post("/v1/ports/feed?port=Slow.inp", data=data, headers=AUTH)
        answer = await resp.json()
        assert (resp.status, text in answer.get("error", "")) == (400, True), (data, answer)


async def test_two_ports_recorded_together_get_a_channel_each_and_a_duration_ends_it(
    agent, tmp_path
):
    client, manager = agent
    await run(manager, POSES, COUNTER)
    api = ["--api", str(client.make_url("")).rstrip("/"), "--token", TOKEN]
    out = tmp_path / "two.mcap"
    argv = ["port", "record", "Poses.pose", "Pub.out", "-o", str(out), "--duration", "1", *api]
    assert await asyncio.to_thread(cli_main, argv) == 0
    with out.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        schemas = {c.topic: summary.schemas[c.schema_id].name for c in summary.channels.values()}
        messages = [(c.topic, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
    topics = [topic for topic, _ in messages]
    assert schemas == {"Poses.pose": POSE, "Pub.out": "sdrpeer/any"}
    assert topics.count("Poses.pose") > 10  # 100 Hz for about a second
    assert topics.count("Pub.out") > 10  # 200 Hz
    numbers = [msgpack.unpackb(data) for topic, data in messages if topic == "Pub.out"]
    assert numbers == list(range(numbers[0], numbers[0] + len(numbers)))  # none missing
    await until_async("the tap's connections removed", lambda: not manager.adhoc_connections())


async def test_typed_images_record_as_their_wire_bytes_and_replay_into_a_typed_port(
    agent, tmp_path
):
    client, manager = agent
    await run(manager, MONO, IMAGE_KEEPER)
    api = ["--api", str(client.make_url("")).rstrip("/"), "--token", TOKEN]
    out = tmp_path / "mono.mcap"
    argv = ["port", "record", "Mono.image", "-o", str(out), "--count", "10", *api]
    assert await asyncio.to_thread(cli_main, argv) == 0
    recorded = [m.data for m in read_recording(out)]
    assert len(recorded) == 10
    for data in recorded:  # the array of its fields, the pixels a bin 32 blob at the end
        assert data[:1] == b"\x97"
        assert data[-76_800 - 5 : -76_800] == b"\xc6" + (76_800).to_bytes(4, "big")
    wires = [msgpack.unpackb(d) for d in recorded]
    argv = ["port", "replay", str(out), "--map", "Mono.image=ImageKeep.image", "--speed", "0"]
    assert await asyncio.to_thread(cli_main, [*argv, *api]) == 0
    kept = await until_answer(
        "10 images taken", lambda: manager.snapshot("ImageKeep"), lambda v: len(v) >= 10
    )
    assert kept == [[w[0], w[6][0], 76_800] for w in wires]
