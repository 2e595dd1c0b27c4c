"""The shared-memory path: the ring's rules, its use on Unix sockets, fallback, repoint, crashes."""

from __future__ import annotations

import asyncio
import os
import signal
import subprocess
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import msgpack
import pytest

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.frames import Hello, encode_hello
from sdrpeer.dataplane.shm import ReceiverRing, SenderRing, ref_frame, sweep
from sdrpeer.dataplane.testing import RecordingPort, make_policy
from sdrpeer.errors import FrameError
from tests.wait import until_async

ROOT = Path(__file__).resolve().parent.parent
SHM = Path("/dev/shm")
pytestmark = pytest.mark.skipif(not SHM.is_dir(), reason="no /dev/shm")


def segments(pid: int | None = None) -> list[str]:
    """Names of ring segments in /dev/shm (of one pid's senders if given)."""
    prefix = "sdrpeer-dp-" if pid is None else f"sdrpeer-dp-{pid}-"
    return [name for name in os.listdir(SHM) if name.startswith(prefix)]


def mapped_segments() -> list[str]:
    """Ring segments this process still maps."""
    return [
        line for line in Path("/proc/self/maps").read_text().splitlines() if "sdrpeer-dp-" in line
    ]


def pair(size: int = 1024, max_frame: int = 1 << 20) -> tuple[SenderRing, ReceiverRing]:
    sender = SenderRing.create(size)
    assert sender is not None
    receiver = ReceiverRing.attach(sender.offer_map(), max_frame)
    assert segments(os.getpid()) == []  # the receiver unlinked the name at once
    return sender, receiver


def test_ring_places_wraps_and_waits_for_credit() -> None:
    sender, receiver = pair(1024)
    value = msgpack.packb(os.urandom(300))
    positions = [sender.place(b"", value) for _ in range(3)]
    assert positions == [0, len(value), 2 * len(value)]
    assert sender.place(b"", value) is None  # 3 x 302 bytes used, 302 more do not fit
    assert sender.is_blocked()
    frames = [receiver.check([i + 1, pos, len(value)]) for i, pos in enumerate(positions)]
    taken = receiver.take(frames[0])
    sender.credit(receiver.consumed)
    assert not sender.is_blocked()
    assert sender.place(b"", value) == 1024  # not across the wrap: the next lap starts at 0
    assert taken == msgpack.unpackb(value)  # a copy: still intact after its bytes were reused
    sender.close()
    receiver.close()


def test_ring_frames_outside_the_ring_are_refused() -> None:
    sender, receiver = pair(1024, max_frame=500)
    cases: list[tuple[list[Any], str]] = [
        ([1, 1000, 100], "malformed"),  # across the end
        ([1, 0, 0], "malformed"),
        (["1", 0, 10], "malformed"),
        ([1, 0, 600], "oversized"),
    ]
    for frame, reason in cases:
        with pytest.raises(FrameError) as info:
            receiver.check(frame)
        assert info.value.reason == reason
    receiver.check([1, 100, 10])
    with pytest.raises(FrameError, match="outside the ring"):
        receiver.check([2, 50, 10])  # positions only go forward
    with pytest.raises(FrameError, match="credit"):
        sender.credit(5000)  # more than was ever placed
    sender.close()
    receiver.close()


def test_sweep_removes_names_of_dead_senders() -> None:
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    left = SHM / f"sdrpeer-dp-{proc.pid}-0123456789abcdef"
    left.write_bytes(b"x")
    mine = SHM / f"sdrpeer-dp-{os.getpid()}-0123456789abcdef"
    mine.write_bytes(b"x")
    try:
        assert sweep() >= 1
        assert not left.exists()
        assert mine.exists()  # alive: not ours to remove
    finally:
        mine.unlink()


class Receiver:
    def __init__(self, path: Path, *, shm: bool = True) -> None:
        self.port = RecordingPort()
        self.server = DataServer(lambda name: self.port, unix_path=str(path), shm=shm)

    def address(self, kind: str) -> str:
        return f"{kind}://{self.server.addresses[kind]}"


async def offer_all(conn: Connection, values: Sequence[object]) -> None:
    for value in values:
        while not conn.offer(value):
            await conn.drain()


VALUES: list[object] = [
    1,
    os.urandom(70_000),
    "s",
    os.urandom(1_000_000),
    {"k": os.urandom(100_000)},
]


@pytest.mark.parametrize("shm", [True, False])
async def test_unix_connection_takes_the_ring_unless_refused(tmp_path: Path, shm: bool) -> None:
    rx = Receiver(tmp_path / "rx.sock", shm=shm)
    await rx.server.start()
    conn = Connection("c", rx.address("unix"), "in", "a.b", make_policy("fifo", 4, "block"))
    conn.start()
    values = VALUES * 20
    await offer_all(conn, values)
    await until_async(
        "len(rx.port.frames) == len(values)",
        lambda: len(rx.port.frames),
        lambda v: v == len(values),
    )
    assert rx.port.values == values
    assert rx.port.seqs == list(range(1, len(values) + 1))
    assert rx.server.counters["shm"] == (1 if shm else 0)
    assert rx.server.bytes_in["in"] == conn.bytes_out
    assert segments(os.getpid()) == []
    await conn.close()
    await rx.server.close()
    assert mapped_segments() == []


async def test_tcp_connection_never_offers_a_ring(tmp_path: Path) -> None:
    rx = Receiver(tmp_path / "rx.sock")
    await rx.server.start()
    conn = Connection("c", rx.address("tcp"), "in", "a.b", make_policy("fifo", 4, "block"))
    conn.start()
    await offer_all(conn, VALUES)
    await until_async(
        "len(rx.port.frames) == len(VALUES)",
        lambda: len(rx.port.frames),
        lambda v: v == len(VALUES),
    )
    assert rx.port.values == VALUES
    assert rx.server.counters["shm"] == 0
    await conn.close()
    await rx.server.close()


async def test_repoint_between_ring_and_tcp_loses_nothing(tmp_path: Path) -> None:
    first, second = Receiver(tmp_path / "a.sock"), Receiver(tmp_path / "b.sock")
    await first.server.start()
    await second.server.start()
    conn = Connection("c", first.address("unix"), "in", "a.b", make_policy("fifo", 4, "block"))
    conn.start()
    values = [os.urandom(200_000) if i % 3 else i for i in range(300)]
    sender = asyncio.create_task(offer_all(conn, values))
    targets = [second.address("tcp"), first.address("unix"), second.address("unix")]
    try:
        mark = 0
        for to in targets:
            # frames only flow through a link that is up: 30 more after the last repoint mean
            # that link's dial (and its ring) was made, however fast the sender runs
            goal = min(mark + 30, len(values))
            await until_async(
                f"seq {goal} sent",
                lambda: conn.seq,
                lambda v, goal=goal: v >= goal,  # type: ignore[misc]
            )
            conn.repoint(to)
            mark = conn.seq
        await asyncio.wait_for(sender, 20)
        # the sender may finish before the last repoint's dial: wait for that link
        await asyncio.wait_for(conn.wait_connected(), 5)
        received = lambda: first.port.frames + second.port.frames  # noqa: E731
        await until_async(
            "len(received()) == len(values)",
            lambda: len(received()),
            lambda v: v == len(values),
            within=20,
        )
        by_seq = sorted(received(), key=lambda frame: frame[0])
        assert [seq for seq, _, _ in by_seq] == list(range(1, len(values) + 1))  # no gap, twice
        assert [value for _, value, _ in by_seq] == values
        assert first.server.counters["shm"] == 2
        assert second.server.counters["shm"] == 1
    finally:
        sender.cancel()
        await conn.close()
        await first.server.close()
        await second.server.close()
    assert mapped_segments() == []


async def test_bad_ring_frame_refused_and_closed(tmp_path: Path) -> None:
    rx = Receiver(tmp_path / "rx.sock")
    await rx.server.start()
    ring = SenderRing.create(4096)
    assert ring is not None
    reader, writer = await asyncio.open_unix_connection(rx.server.addresses["unix"])
    writer.write(encode_hello(Hello("raw", "in", "x.y", {}, shm=ring.offer_map())))
    assert msgpack.unpackb(await reader.read(100)) == {"ok": True, "shm": True}
    pos = ring.place(b"", msgpack.packb("fine"))
    assert pos is not None
    writer.write(ref_frame(1, pos, 5) + ref_frame(2, 4000, 500))  # the second is outside
    assert await reader.read(100) == msgpack.packb(5)  # the credit for the first
    await until_async(
        "rx.server.counters['refused_malformed'] == 1",
        lambda: rx.server.counters["refused_malformed"],
        lambda v: v == 1,
    )
    assert rx.port.values == ["fine"]
    assert rx.port.refused == 1
    assert await reader.read(100) == b""  # closed
    writer.close()
    ring.close()
    await rx.server.close()


PEER = """
import asyncio, os, sys
from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.testing import RecordingPort, make_policy

async def send(to):
    conn = Connection("k", to, "in", "peer.out", make_policy("fifo", 4, "block"))
    conn.start()
    value = os.urandom(500_000)
    while True:
        while not conn.offer(value):
            await conn.drain()

async def receive(path):
    server = DataServer(lambda name: RecordingPort(), unix_path=path)
    await server.start()
    print("ready", flush=True)
    await asyncio.Event().wait()

asyncio.run(send(sys.argv[2]) if sys.argv[1] == "send" else receive(sys.argv[2]))
"""


def spawn(*args: str) -> subprocess.Popen[str]:
    return subprocess.Popen(
        [sys.executable, "-c", PEER, *args], cwd=ROOT, stdout=subprocess.PIPE, text=True
    )


def stop(proc: subprocess.Popen[str]) -> None:
    proc.kill()
    proc.wait(10)
    if proc.stdout is not None:
        proc.stdout.close()


async def test_sigkilled_sender_leaves_no_segment(tmp_path: Path) -> None:
    rx = Receiver(tmp_path / "rx.sock")
    await rx.server.start()
    proc = spawn("send", rx.address("unix"))
    try:
        await until_async(
            "len(rx.port.frames) > 20", lambda: len(rx.port.frames), lambda v: v > 20, within=20
        )
        assert rx.server.counters["shm"] == 1
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        await until_async(
            "rx.server.connections == 0", lambda: rx.server.connections, lambda v: v == 0
        )
        assert segments(proc.pid) == []
        assert mapped_segments() == []  # the receiver unmapped it: the memory is free
    finally:
        stop(proc)
        await rx.server.close()


async def test_sigkilled_receiver_leaves_no_segment(tmp_path: Path) -> None:
    path = tmp_path / "rx.sock"
    proc = spawn("receive", str(path))
    conn = Connection(
        "k", f"unix://{path}", "in", "a.b", make_policy("fifo", 4, "block"), backoff=(0.01, 0.05)
    )
    try:
        assert proc.stdout is not None
        assert await asyncio.to_thread(proc.stdout.readline) == "ready\n"
        conn.start()
        value = os.urandom(500_000)
        await offer_all(conn, [value] * 50)
        await until_async(
            "conn.connected and conn.seq >= 20", lambda: conn.connected and conn.seq >= 20
        )
        assert mapped_segments() != []
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait(10)
        await until_async("not conn.connected", lambda: not conn.connected)
        assert segments(os.getpid()) == segments(proc.pid) == []
        assert mapped_segments() == []
    finally:
        await conn.close(linger=0.1)
        stop(proc)
