"""An in-process link (a composite's member feeding another): every value is in the InPort at
once, with the connection's receive-side policy over the port's, and counted on both sides."""

from __future__ import annotations

from sdrpeer.host.local_link import LocalLink
from sdrpeer.sdk import (
    ConnectorPolicy,
    Image,
    InPortRuntime,
    Odometry,
    OutPortRuntime,
    Pose,
    Velocity,
)
from sdrpeer.sdk.typed import BLOB_MIN


def linked(
    port_policy: dict[str, object], given: dict[str, object]
) -> tuple[OutPortRuntime, InPortRuntime, LocalLink]:
    out = OutPortRuntime("out")
    inp = InPortRuntime("inp", ConnectorPolicy.from_map(port_policy))
    link = LocalLink("c", inp, given)
    out.attach(link)
    return out, inp, link


def test_values_are_queued_at_once_with_the_connections_buffer_over_the_ports() -> None:
    out, inp, _ = linked({"buffer": 2, "full": "overwrite"}, {"buffer": 3})
    for v in range(5):
        out.write(v)
    assert [inp.get_nowait() for _ in range(inp.qsize())] == [2, 3, 4]  # buffer 3, overwrite
    assert out.counters()["frames_sent"] == 5
    assert inp.counters()["frames_in"] == 5
    assert inp.counters()["dropped"] == 2


def test_push_new_keeps_the_newest_and_block_is_not_unbounded() -> None:
    out, inp, _ = linked({"buffer": 4}, {"push": "new"})
    for v in range(3):
        out.write(v)
    assert [inp.get_nowait() for _ in range(inp.qsize())] == [2]
    out, inp, _ = linked({"buffer": 2, "full": "drop"}, {"full": "block"})
    for v in range(4):
        out.write(v)
    assert inp.qsize() == 2  # nothing acknowledges an in-process link: the port's `drop` holds


def test_close_forgets_the_connection_and_keeps_what_is_queued() -> None:
    out, inp, link = linked({"buffer": 8}, {"push": "skip", "skip": 1})
    for v in range(4):
        out.write(v)
    link.close()
    out.detach(link)
    assert [inp.get_nowait() for _ in range(inp.qsize())] == [0, 2]  # every second one
    assert out.counters()["frames_sent"] == 4  # a detached link's counts stay with the port


def test_typed_values_arrive_as_their_type_nested_and_with_a_big_blob() -> None:
    odom = Odometry(1.5, "odom", "base", Pose(1.5, "odom", 1.0, 2.0), Velocity(1.5, "base", 0.5))
    out = OutPortRuntime("out", port_type=Odometry)
    inp = InPortRuntime("inp", ConnectorPolicy(buffer=4), port_type=Odometry)
    out.attach(LocalLink("c", inp, {}))
    out.write(odom)
    assert inp.get_nowait() == odom
    assert inp.counters()["refused"] == 0
    image = Image(2.0, "cam", 256, 256, "mono8", 256, b"\x07" * BLOB_MIN)  # sent as a WireBlob
    out = OutPortRuntime("out", port_type=Image)
    inp = InPortRuntime("inp", ConnectorPolicy(buffer=4), port_type=Image)
    out.attach(LocalLink("c", inp, {}))
    out.write(image)
    assert inp.get_nowait() == image
