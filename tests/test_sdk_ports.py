"""Ports: connector policies at the InPort, loss counting, OutPort fan-out and backpressure."""

from __future__ import annotations

import asyncio
from typing import Any

import pytest

from sdrpeer.sdk import Component, ConnectorPolicy, InPort, NoData, OutPort
from sdrpeer.sdk.ports import InPortRuntime, OutPortRuntime

# -- ConnectorPolicy ---------------------------------------------------------------------


def test_policy_defaults_and_maps() -> None:
    assert ConnectorPolicy.from_map({}) == ConnectorPolicy("all", 8, "overwrite", 0)
    assert ConnectorPolicy.from_map(None) == ConnectorPolicy()
    p = ConnectorPolicy.from_map({"push": "skip", "skip": 2, "extra": "ignored"})
    assert p.to_map() == {
        "push": "skip",
        "buffer": 8,
        "full": "overwrite",
        "skip": 2,
        "encrypt": True,
    }
    assert ConnectorPolicy.from_map(p.to_map()) == p
    assert not ConnectorPolicy.from_map({"encrypt": False}).encrypt


@pytest.mark.parametrize(
    ("data", "fragment"),
    [
        ({"push": "some"}, "policy push: 'some'"),
        ({"full": "explode"}, "policy full: 'explode'"),
        ({"buffer": 0}, "policy buffer: 0"),
        ({"buffer": "8"}, "policy buffer: '8'"),
        ({"encrypt": "no"}, "policy encrypt: 'no'"),
        ({"buffer": True}, "policy buffer: True"),
        ({"skip": -1}, "policy skip: -1"),
    ],
)
def test_policy_validation(data: dict[str, Any], fragment: str) -> None:
    with pytest.raises(ValueError, match="policy") as info:
        ConnectorPolicy.from_map(data)
    assert fragment in str(info.value)


def test_policy_is_frozen() -> None:
    p = ConnectorPolicy()
    with pytest.raises(AttributeError):
        p.buffer = 3  # type: ignore[misc]


# -- InPort ------------------------------------------------------------------------------


def port(**policy: Any) -> InPortRuntime:
    return InPortRuntime("in", ConnectorPolicy(**policy))


def feed(p: InPortRuntime, values: range | list[int], conn: str = "c1") -> None:
    for v in values:
        p.deliver(v, v, conn)


def drain(p: InPortRuntime) -> list[Any]:
    out = []
    while p.qsize():
        out.append(p.get_nowait())
    return out


def test_fifo_under_capacity_keeps_everything_in_order() -> None:
    p = port(push="fifo", buffer=4)
    feed(p, range(1, 4))
    assert drain(p) == [1, 2, 3]
    assert p.counters()["dropped"] == 0


def test_fifo_full_overwrite_evicts_the_oldest() -> None:
    p = port(push="fifo", buffer=3, full="overwrite")
    feed(p, range(1, 6))
    assert drain(p) == [3, 4, 5]
    assert p.counters()["dropped"] == 2
    assert p.counters()["frames_in"] == 5


def test_fifo_full_drop_refuses_the_newest() -> None:
    p = port(push="fifo", buffer=3, full="drop")
    feed(p, range(1, 6))
    assert p.read() == 3  # the newest *accepted* value
    feed(p, [6])
    assert drain(p) == [6]
    assert p.counters()["dropped"] == 2


def test_full_block_never_drops_and_reports_no_space() -> None:
    p = port(buffer=2, full="block")
    feed(p, range(1, 5))
    assert p.qsize() == 4
    assert p.counters()["dropped"] == 0
    assert not p.has_space("c1")


async def test_wait_space_returns_when_the_reader_catches_up() -> None:
    p = port(buffer=2, full="block")
    feed(p, range(1, 4))
    waiter = asyncio.ensure_future(p.wait_space("c1"))
    await asyncio.sleep(0)
    assert not waiter.done()
    p.get_nowait()
    await asyncio.sleep(0)
    assert not waiter.done()  # 2 queued, buffer 2: still no room
    p.get_nowait()
    await asyncio.wait_for(waiter, 1.0)


def test_new_keeps_only_the_newest() -> None:
    p = port(push="new", buffer=8)
    feed(p, range(1, 6))
    assert p.qsize() == 1
    assert p.get_nowait() == 5
    assert p.counters()["dropped"] == 4


@pytest.mark.parametrize(
    ("skip", "kept"), [(0, [1, 2, 3, 4, 5, 6, 7]), (1, [1, 3, 5, 7]), (2, [1, 4, 7])]
)
def test_skip_keeps_one_of_every_skip_plus_one(skip: int, kept: list[int]) -> None:
    p = port(push="skip", skip=skip, buffer=16)
    feed(p, range(1, 8))
    assert drain(p) == kept
    c = p.counters()
    assert c["skipped"] == 7 - len(kept)
    assert c["dropped"] == 0
    assert c["frames_in"] == 7


def test_lost_counts_sequence_gaps() -> None:
    p = port(buffer=100)
    feed(p, [1, 2, 5, 6, 10])
    assert p.counters()["lost"] == 2 + 3


def test_first_frame_sets_the_baseline_and_a_restart_is_not_loss() -> None:
    p = port(buffer=100)
    feed(p, [7, 8, 9])  # joined late (e.g. after a repoint): nothing counted
    feed(p, [1, 2, 4])  # the sender restarted at 1, then lost 3
    assert p.counters()["lost"] == 1


def test_seq_is_tracked_per_connection() -> None:
    p = port(buffer=100)
    p.deliver("a", 1, "A")
    p.deliver("b", 1, "B")
    p.deliver("a", 2, "A")
    p.deliver("b", 2, "B")
    p.deliver("b", 3, "B")
    assert p.counters()["lost"] == 0  # interleaving connections is not a gap
    p.deliver("a", 5, "A")
    assert p.counters()["lost"] == 2
    assert drain(p) == ["a", "b", "a", "b", "b", "a"]


def test_per_connection_policy_overrides_the_port_default() -> None:
    p = port(buffer=8)
    p.connect("thin", ConnectorPolicy(push="skip", skip=1))
    assert p.policy_for("thin").push == "skip"
    assert p.policy_for("other") == p.policy
    for seq in range(1, 5):
        p.deliver(("thin", seq), seq, "thin")
        p.deliver(("full", seq), seq, "other")
    assert drain(p) == [
        ("thin", 1),
        ("full", 1),
        ("full", 2),
        ("thin", 3),
        ("full", 3),
        ("full", 4),
    ]
    p.disconnect("thin")
    assert p.policy_for("thin") == p.policy


def test_read_returns_newest_and_consumes_the_queue() -> None:
    p = port()
    with pytest.raises(NoData, match="in-port 'in': no data"):
        p.read()
    assert not p.is_new()
    feed(p, [1, 2, 3])
    assert p.is_new()
    assert p.read() == 3
    assert not p.is_new()
    assert p.qsize() == 0
    assert p.read() == 3  # still the newest
    with pytest.raises(NoData, match="queue is empty"):
        p.get_nowait()


def test_counters_frames_and_refused() -> None:
    p = port()
    p.deliver(b"abcd", 1, "c")
    p.deliver("xy", 2, "c")
    p.deliver({"a": 1}, 3, "c")
    p.deliver(memoryview(b"12345"), 4, "c")
    p.refuse()
    c = p.counters()
    assert c["bytes_in"] == 0  # the data plane counts bytes (a host reports its server's)
    assert c["refused"] == 1
    assert c["frames_in"] == 4
    assert set(c) >= {"frames_in", "bytes_in", "frames_out", "bytes_out", "dropped", "lost"}


async def test_async_iteration_waits_and_yields_in_arrival_order() -> None:
    p = port(buffer=8)
    got: list[Any] = []

    async def reader() -> None:
        async for value in p:
            got.append(value)
            if len(got) == 3:
                return

    task = asyncio.ensure_future(reader())
    await asyncio.sleep(0)
    assert got == []
    p.deliver("a", 1, "c")
    p.deliver("b", 2, "c")
    await asyncio.sleep(0)
    p.deliver("c", 3, "c")
    await asyncio.wait_for(task, 1.0)
    assert got == ["a", "b", "c"]


async def test_a_cancelled_reader_does_not_break_the_other() -> None:
    p = port()
    first = asyncio.ensure_future(p.get())
    second = asyncio.ensure_future(p.get())
    await asyncio.sleep(0)
    first.cancel()
    await asyncio.sleep(0)
    p.deliver("x", 1, "c")
    assert await asyncio.wait_for(second, 1.0) == "x"


# -- OutPort -----------------------------------------------------------------------------


class FakeSink:
    """A FrameSink that keeps what it is offered and can refuse when full."""

    def __init__(self, capacity: int = 1000) -> None:
        self.capacity = capacity
        self.got: list[Any] = []
        self.bytes_out = 0

    def offer(self, value: Any) -> bool:
        if len(self.got) >= self.capacity:
            return False
        self.got.append(value)
        self.bytes_out += 10
        return True


class BlockingSink(FakeSink):
    """A full="block" sink: drain() waits until the test frees room."""

    def __init__(self, capacity: int) -> None:
        super().__init__(capacity)
        self.room = asyncio.Event()

    async def drain(self) -> None:
        while len(self.got) >= self.capacity:
            self.room.clear()
            await self.room.wait()

    def take(self) -> None:
        self.got.clear()
        self.room.set()


def test_write_fans_out_to_every_sink_without_copying() -> None:
    out = OutPortRuntime("o")
    a, b = FakeSink(), FakeSink(capacity=1)
    out.attach(a)
    out.attach(b)
    out.attach(a)  # twice is once
    frame = {"img": bytearray(3)}
    out.write(frame)
    out.write("second")
    assert a.got == [frame, "second"]
    assert a.got[0] is frame
    assert b.got == [frame]
    c = out.counters()
    assert c["frames_out"] == 2
    assert c["dropped"] == 1  # b refused the second
    assert c["bytes_out"] == 30
    out.detach(a)
    out.write("third")
    assert a.got == [frame, "second"]
    assert out.counters()["bytes_out"] == 30  # a's bytes are kept after detach
    assert out.sinks == (b,)


def test_write_without_sinks_only_counts() -> None:
    out = OutPortRuntime("o")
    out.write(b"x")
    assert out.counters()["frames_out"] == 1


async def test_send_blocks_on_a_full_block_sink_until_drained() -> None:
    out = OutPortRuntime("o")
    sink = BlockingSink(capacity=2)
    other = FakeSink()
    out.attach(sink)
    out.attach(other)
    await out.send(1)
    await out.send(2)
    third = asyncio.ensure_future(out.send(3))
    for _ in range(5):
        await asyncio.sleep(0)
    assert not third.done()
    assert sink.got == [1, 2]
    assert other.got == [1, 2]  # nothing was written while waiting
    sink.take()
    await asyncio.wait_for(third, 1.0)
    assert sink.got == [3]
    assert other.got == [1, 2, 3]


# -- descriptors -------------------------------------------------------------------------


class Pipe(Component):
    image = InPort("camera frames", policy={"push": "new"})
    result = OutPort("detections")


def test_each_instance_gets_its_own_named_ports() -> None:
    a, b = Pipe("a"), Pipe("b")
    assert isinstance(a.image, InPortRuntime)
    assert a.image is not b.image
    assert a.image.name == "image"
    assert a.result.name == "result"
    assert a.image.policy.push == "new"
    assert a.inport("image") is a.image
    assert a.outport("result") is a.result
    assert isinstance(Pipe.image, InPort)


def test_port_metadata() -> None:
    assert Pipe.port_names() == {"in": ["image"], "out": ["result"]}
    info = Pipe.ports()
    assert info["image"].kind == "in"
    assert info["image"].doc == "camera frames"
    assert info["result"].to_map() == {"name": "result", "kind": "out", "doc": "detections"}
    assert info["image"].to_map()["policy"]["push"] == "new"
    counters = Pipe().port_counters()
    assert set(counters) == {"image", "result"}
