"""Port recordings as MCAP (sdrpeer.ports.mcapfile): what is written reads back the same with the
`mcap` reader and ours; publish times; the JSON Schema of a type; files cut short or not MCAP."""

from __future__ import annotations

import json
from pathlib import Path

import msgpack
import pytest
from mcap.reader import make_reader

from sdrpeer.cli.port import replay_chunks
from sdrpeer.ports.mcapfile import (
    RecordingWriter,
    publish_ns,
    read_recording,
    recorded_channels,
    schema_for,
)
from sdrpeer.ports.values import schema_fields
from sdrpeer.sdk.robot_types import Pose
from sdrpeer.sdk.typed import MessageType, message_type

_POSE = message_type(Pose)
assert _POSE is not None
POSE: MessageType = _POSE
FIELDS = schema_fields(POSE)


def write(path: Path, n: int, chunk_size: int = 1 << 20) -> list[bytes]:
    """n Pose messages on one channel and n blobs on another, interleaved."""
    datas = []
    with path.open("wb") as f:
        writer = RecordingWriter(f, chunk_size)
        pose = writer.add_port("Odo.pose", POSE.type_id, FIELDS, "robot-1")
        blob = writer.add_port("Cam.image", None, [], "robot-2")
        for i in range(n):
            wire = [float(i), "map", float(i), 0.0, 0.0, 0.0, 0.0, 0.0, 1.0]
            datas.append(msgpack.packb(wire))
            writer.write(pose, 1000 + i, publish_ns(wire, FIELDS, 1000 + i), i + 1, datas[-1])
            datas.append(msgpack.packb({"ts": 2.5, "pixels": bytes([i % 256]) * 70_000}))
            writer.write(blob, 1000 + i, 7, i + 1, datas[-1])
        writer.finish()
    return datas


def test_what_is_written_reads_back_the_same_in_order(tmp_path):
    path = tmp_path / "r.mcap"
    datas = write(path, 20)
    with path.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        got = [(c.topic, m.data) for _, c, m in reader.iter_messages(log_time_order=False)]
    assert [d for _, d in got] == datas
    assert [t for t, _ in got] == ["Odo.pose", "Cam.image"] * 20
    ours = list(read_recording(path))
    assert [m.data for m in ours] == datas
    assert [m.schema for m in ours[:2]] == [POSE.type_id, "sdrpeer/any"]
    assert recorded_channels(path) == {"Odo.pose": POSE.type_id, "Cam.image": "sdrpeer/any"}
    channels = {c.topic: c for c in summary.channels.values()}
    assert channels["Cam.image"].metadata == {
        "instance": "Cam", "port": "image", "robot": "robot-2", "type": "",
    }  # fmt: skip


def test_a_recording_cut_short_gives_what_it_holds(tmp_path):
    path = tmp_path / "r.mcap"
    datas = write(path, 40, chunk_size=4096)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(path.read_bytes()[: path.stat().st_size // 2])
    got = [m.data for m in read_recording(cut)]
    assert 0 < len(got) < len(datas)
    assert got == datas[: len(got)]
    assert set(recorded_channels(cut)) <= {"Odo.pose", "Cam.image"}


def test_a_file_that_is_not_mcap_is_a_clear_error(tmp_path):
    path = tmp_path / "x.mcap"
    path.write_bytes(b"garbage, not a recording")
    with pytest.raises(ValueError, match=r"x\.mcap: not a readable MCAP recording"):
        recorded_channels(path)


@pytest.mark.parametrize(
    ("value", "fields", "want"),
    [
        ([1.5, "map", 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0], FIELDS, 1_500_000_000),
        ({"ts": 2.0, "x": 1}, [], 2_000_000_000),
        ({"stamp": 3.0, "ts": 2.0}, [], 3_000_000_000),
        ({"x": 1}, [], 99),  # no time of its own: the receive time
        (5, [], 99),
        ({"ts": True}, [], 99),
        ({"ts": -1.0}, [], 99),
        ([1.5, "map"], FIELDS, 99),  # not of the type's shape
    ],
)
def test_publish_time_is_the_frames_own_time_else_the_receive_time(value, fields, want):
    assert publish_ns(value, fields, 99) == want


def test_a_typed_schema_lists_its_fields_in_order():
    doc = schema_for(POSE.type_id, FIELDS)
    assert doc["title"] == doc["x-sdrpeer-type"] == POSE.type_id
    assert [i["title"] for i in doc["prefixItems"]] == [f for f, _ in FIELDS]
    assert doc["prefixItems"][0]["type"] == "number"
    assert doc["prefixItems"][1]["type"] == "string"
    assert doc["items"] is False
    assert json.loads(json.dumps(doc)) == doc
    assert schema_for(None, [])["title"] == "sdrpeer/any"


def test_replay_sends_the_recorded_bytes_in_order_and_loops_on_request(tmp_path):
    path = tmp_path / "r.mcap"
    datas = write(path, 5)
    counts: dict[str, int] = {}
    index = {"Odo.pose": 0, "Cam.image": 1}
    chunks = replay_chunks(path, index, 0.0, True, counts)
    got = [next(chunks) for _ in range(3 * len(datas))]  # three times round
    want = [b"\x92" + msgpack.packb(i % 2) + d for i, d in enumerate(datas)]
    assert got == want * 3
    assert [msgpack.unpackb(c)[1] for c in got[:2]] == [msgpack.unpackb(d) for d in datas[:2]]
    assert counts == {"Odo.pose": 15, "Cam.image": 15}
    only_pose = list(replay_chunks(path, {"Odo.pose": 0}, 0.0, False, {}))
    assert only_pose == want[::2]  # a channel not asked for is left out
