"""Acknowledged streams: the sender's window, the InPort's acks, replay on repoint and crash."""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from pathlib import Path

import pytest

from sdrpeer.dataplane import Connection, DataServer
from sdrpeer.dataplane.retention import Retention
from sdrpeer.dataplane.testing import RecordingPort, make_policy
from sdrpeer.sdk.acks import AckState
from sdrpeer.sdk.inport import InPortRuntime
from sdrpeer.sdk.policy import ConnectorPolicy
from tests.wait import stays_async, until_async

# ---- the pure parts ------------------------------------------------------------------------


def is_full(r: Retention[bytes]) -> bool:
    return r.full  # a call: mypy does not narrow it across the writes in between


def test_retention_holds_frames_until_acknowledged() -> None:
    r: Retention[bytes] = Retention(max_frames=4, max_bytes=1000)
    r.written([b"a", b"bb", b"ccc"])
    r.wrote(b"dddd")
    assert is_full(r)
    assert r.bytes == 10
    assert r.unacked() == [(1, b"a"), (2, b"bb"), (3, b"ccc"), (4, b"dddd")]
    assert r.ack(2) == 2
    assert not is_full(r)
    assert r.bytes == 7
    assert r.base == 3
    assert r.ack(2) == 0
    assert r.ack(1) == 0
    assert r.ack(9) == 0  # not written yet: ignored
    assert r.unacked() == [(3, b"ccc"), (4, b"dddd")]
    assert r.base + len(r) == 5  # the next frame written gets seq 5
    r = Retention(first_seq=12)  # acknowledged from seq 12 on
    assert len(r) == 0
    assert r.base == 12
    assert r.acked == 11


def test_retention_window_counts_bytes_too() -> None:
    r: Retention[bytes] = Retention(max_frames=100, max_bytes=10)
    r.wrote(b"x" * 9)
    assert not is_full(r)
    r.wrote(b"y")
    assert is_full(r)
    with pytest.raises(ValueError, match="at least one"):
        Retention(max_frames=0)


def test_ack_state_waits_for_older_frames_before_a_refused_one() -> None:
    sent = Acks()
    a = AckState("s", 1, sent)
    a.enq = 2  # frames 1 and 2 queued
    a.refused(3)  # 3 dropped on arrival while 1, 2 wait
    assert a.acked == 0
    a.taken(1)
    a.flush()
    assert sent == [1]
    a.enq += 1  # frame 4 queued
    a.taken(2)  # now 3 is handled too
    a.flush()
    assert sent == [1, 3]
    a.taken(4)
    a.flush()
    a.flush()  # nothing new: nothing sent
    assert sent == [1, 3, 4]
    assert sent.dropped == 1  # frame 3, told with the ack that covered it


# ---- the InPort's side ---------------------------------------------------------------------


class Acks(list[int]):
    """What a stream's acknowledgements said: the seqs (in order) and the drops they reported."""

    def __init__(self) -> None:
        super().__init__()
        self.dropped = 0

    def __call__(self, seq: int, dropped: int) -> None:
        self.append(seq)
        self.dropped += dropped


def ignore(seq: int, dropped: int) -> None:
    """Acknowledgements nobody reads."""


def port_with_stream(
    policy: ConnectorPolicy | None = None,
) -> tuple[InPortRuntime, Acks, str]:
    port = InPortRuntime("in", policy or ConnectorPolicy("fifo", 100, "block"))
    acks = Acks()
    key = port.attach_stream("c", "session-1", 1, acks)
    return port, acks, key


def test_inport_acknowledges_what_the_component_took() -> None:
    port, acks, key = port_with_stream()
    for seq in range(1, 6):
        port.deliver(seq * 10, seq, key)
    assert acks == []  # delivered is not taken
    assert port.get_nowait() == 10
    assert port.get_nowait() == 20
    assert acks == [1, 2]  # no loop running: sent at once
    assert port.read() == 50
    assert acks[-1] == 5
    assert port.acked(key) == 5


def test_inport_acknowledges_what_its_policy_discarded() -> None:
    port, acks, key = port_with_stream(ConnectorPolicy("fifo", 2, "overwrite"))
    for seq in (1, 2, 3):
        port.deliver(seq, seq, key)
    assert acks == [1]  # 1 was evicted by 3: it can never be needed again
    assert acks.dropped == 1  # and the sender is told it was thrown away
    port, acks, key = port_with_stream(ConnectorPolicy("fifo", 2, "drop"))
    for seq in (1, 2, 3):
        port.deliver(seq, seq, key)
    assert acks == [0]  # 3 was refused, but 1 and 2 still wait: only the drop is told
    assert acks.dropped == 1
    assert port.get_nowait() == 1
    assert port.get_nowait() == 2
    assert acks == [0, 1, 3]
    assert acks.dropped == 1  # each drop told once


@pytest.mark.parametrize(
    ("policy", "dropped"),
    [
        (ConnectorPolicy("new", 8, "overwrite"), 0),  # replacing is the design, not a loss
        (ConnectorPolicy("skip", 8, "overwrite", skip=1), 0),  # so is thinning
        (ConnectorPolicy("fifo", 4, "overwrite"), 6),
        (ConnectorPolicy("fifo", 4, "drop"), 6),
        (ConnectorPolicy("fifo", 100, "block"), 0),
    ],
)
def test_every_frame_a_policy_discards_is_told_to_the_sender(
    policy: ConnectorPolicy, dropped: int
) -> None:
    """Ten frames into a port nobody reads, then the consumer takes what is left: the acks
    report exactly the frames the port discarded on a full buffer (what `new` replaces and
    `skip` thins out is the policy's purpose, counted at the port only)."""
    port, acks, key = port_with_stream(policy)
    for seq in range(1, 11):
        port.deliver(seq, seq, key)
    while port.qsize():
        port.get_nowait()
    assert acks.dropped == dropped
    if policy.push in ("all", "fifo"):
        assert port.dropped == dropped
    else:
        assert port.dropped + port.skipped == (9 if policy.push == "new" else 5)
    assert acks[-1] == 10  # everything handled


def test_inport_drops_a_replay_within_a_session_and_restarts_on_a_new_one() -> None:
    port, acks, key = port_with_stream()
    for seq in (1, 2, 3):
        port.deliver(seq, seq, key)
    port.get_nowait()
    again = Acks()
    assert port.attach_stream("c", "session-1", 2, again) == key  # a reconnect
    assert again == [1]  # told at once where the port is
    for seq in (2, 3, 4):
        port.deliver(seq, seq, key)
    assert port.duplicates == 2
    assert port.lost == 0
    assert [port.get_nowait() for _ in range(3)] == [2, 3, 4]
    assert again[-1] == 4
    assert acks == [1]
    fresh = Acks()
    new_key = port.attach_stream("c", "session-2", 1, fresh)  # the sender restarted
    port.deliver("x", 1, new_key)
    assert port.get_nowait() == "x"
    assert fresh == [1]
    assert port.duplicates == 2


def test_two_senders_of_one_connection_never_mix() -> None:
    """An old copy of the sender still flushing (session 1) while its successor (session 2)
    starts: each has its own seqs, duplicates and acks."""
    port = InPortRuntime("in", ConnectorPolicy("fifo", 100, "block"))
    old_acks, new_acks = Acks(), Acks()
    old = port.attach_stream("c", "s1", 1, old_acks)
    for seq in range(1, 901):
        port.deliver(seq, seq, old)
    new = port.attach_stream("c", "s2", 1, new_acks)
    port.deliver("n1", 1, new)
    port.deliver(901, 901, old)  # the old socket still delivering
    port.deliver("n2", 2, new)
    assert port.duplicates == 0
    assert port.lost == 0
    taken = [port.get_nowait() for _ in range(port.qsize())]
    assert taken[-3:] == ["n1", 901, "n2"]
    assert old_acks[-1] == 901
    assert new_acks[-1] == 2


def test_sessions_of_a_connection_are_bounded() -> None:
    port = InPortRuntime("in", ConnectorPolicy("fifo", 100, "block"))
    for k in range(20):
        key = port.attach_stream("c", f"s{k}", 1, Acks())
        port.detach_stream(key, ignore)  # not the one attached: stays attached
    assert len(port._conns) == 20  # attached ones are kept
    port2 = InPortRuntime("in", ConnectorPolicy("fifo", 100, "block"))
    for k in range(20):
        send = Acks()
        key = port2.attach_stream("c", f"s{k}", 1, send)
        port2.detach_stream(key, send)
    assert len(port2._conns) <= 5


def test_inport_counts_a_gap_from_the_first_seq_announced() -> None:
    port = InPortRuntime("in", ConnectorPolicy("fifo", 100, "block"))
    key = port.attach_stream("c", "s", 5, ignore)
    port.deliver("a", 7, key)
    assert port.lost == 2


# ---- over real sockets ---------------------------------------------------------------------


class Instance:
    """One receiving instance: a DataServer whose InPort is the SDK's, and a consumer task."""

    def __init__(self, path: Path) -> None:
        self.port = InPortRuntime("in", ConnectorPolicy("fifo", 100_000, "block"))
        self.server = DataServer(
            lambda name: self.port if name == "in" else None, unix_path=str(path)
        )
        self.taken: list[int] = []
        self._consumer: asyncio.Task[None] | None = None

    async def start(self, *, consume: bool = True) -> Instance:
        await self.server.start()
        if consume:
            self.resume()
        return self

    def address(self, kind: str) -> str:
        return f"{kind}://{self.server.addresses[kind]}"

    def resume(self) -> None:
        self.server.set_taking(True)
        self._consumer = asyncio.create_task(self._consume())

    async def _consume(self) -> None:
        async for value in self.port:
            self.taken.append(value)
            if len(self.taken) % 7 == 0:
                await asyncio.sleep(0)  # a component that takes its time

    async def deactivate(self) -> None:
        """What a host does when its component leaves ACTIVE."""
        self.server.set_taking(False)
        if self._consumer is not None:
            self._consumer.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._consumer
            self._consumer = None

    async def stop(self) -> None:
        """A planned stop: take nothing more, tell the senders, close."""
        await self.deactivate()
        await self.server.close()

    async def crash(self) -> None:
        """Like SIGKILL: the sockets vanish, no last acknowledgement."""
        await self.deactivate()
        for receiver in list(self.server._receivers):
            receiver.acking = None
            receiver.abort()
        await self.server.close()


@pytest.fixture
async def instances(tmp_path: Path) -> AsyncIterator[list[Instance]]:
    made: list[Instance] = []
    yield made
    for inst in made:
        await inst.stop()


async def new_instance(made: list[Instance], tmp: Path, *, consume: bool = True) -> Instance:
    inst = Instance(tmp / f"rx{len(made)}.sock")
    made.append(inst)
    return await inst.start(consume=consume)


async def publish(conn: Connection, n: int, every: int = 50) -> None:
    for value in range(1, n + 1):
        while not conn.offer(value):
            await conn.drain()
        if value % every == 0:
            await asyncio.sleep(0.001)  # a sensor's pace, so moves land mid-stream


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_planned_moves_lose_and_duplicate_nothing(
    instances: list[Instance], tmp_path: Path, kind: str
) -> None:
    n, moves = 6000, 5
    current = await new_instance(instances, tmp_path)
    conn = Connection("c", current.address(kind), "in", "cam.out", make_policy("fifo", 64, "block"))
    conn.start()
    sender = asyncio.create_task(publish(conn, n))
    try:
        for _ in range(moves):
            await until_async(
                "ten frames taken, or all sent",
                lambda c=current: (len(c.taken), conn.seq),  # type: ignore[misc]
                lambda seen: seen[0] > 10 or seen[1] >= n,
            )
            await asyncio.sleep(0.01)
            nxt = await new_instance(instances, tmp_path)
            await current.deactivate()  # the plan moved it: it stops taking frames
            conn.repoint(nxt.address(kind))
            await current.stop()  # its unconsumed frames are not acknowledged
            current = nxt
        await asyncio.wait_for(sender, 30)
        taken = lambda: [v for inst in instances for v in inst.taken]  # noqa: E731
        await until_async("len(taken()) >= n", lambda: len(taken()), lambda v: v >= n, within=20)
        assert sorted(taken()) == list(range(1, n + 1))  # every frame once, none lost
        assert conn.replayed > 0  # the moves did leave frames to replay
        assert all(inst.port.duplicates == 0 for inst in instances)
    finally:
        sender.cancel()
        await conn.close(linger=0.5)


async def test_a_deactivated_receiver_lets_its_sender_go_at_once(
    instances: list[Instance], tmp_path: Path
) -> None:
    """The old instance was deactivated for a move: when its sender re-points, it sends the
    acks due and closes at once, so the new instance gets the rest without the drain wait."""
    first = await new_instance(instances, tmp_path)
    conn = Connection("c", first.address("tcp"), "in", "cam.out", make_policy("fifo", 64, "block"))
    conn.start()
    sender = asyncio.create_task(publish(conn, 100_000, every=10))
    try:
        await until_async("len(first.taken) > 200", lambda: len(first.taken), lambda v: v > 200)
        await first.deactivate()
        await until_async("conn.unacked > 0", lambda: conn.unacked, lambda v: v > 0)
        second = await new_instance(instances, tmp_path)
        t0 = asyncio.get_running_loop().time()
        conn.repoint(second.address("tcp"))
        await until_async(
            "len(second.taken) > 0", lambda: len(second.taken), lambda v: v > 0, within=3
        )
        assert asyncio.get_running_loop().time() - t0 < conn.drain_timeout / 2
        sender.cancel()
        await until_async(
            "conn.unacked == 0 and not conn.pending",
            lambda: conn.unacked == 0 and not conn.pending,
            within=5,
        )
        taken = first.taken + second.taken
        assert sorted(taken) == list(range(1, len(taken) + 1))  # none lost, none twice
    finally:
        sender.cancel()
        await conn.close(linger=0.5)


async def test_a_crashed_receiver_loses_nothing_the_window_held(
    instances: list[Instance], tmp_path: Path
) -> None:
    n = 4000
    first = await new_instance(instances, tmp_path)
    conn = Connection("c", first.address("tcp"), "in", "cam.out", make_policy("fifo", 64, "block"))
    conn.start()
    sender = asyncio.create_task(publish(conn, n))
    try:
        await until_async("len(first.taken) > 1000", lambda: len(first.taken), lambda v: v > 1000)
        await first.crash()
        second = await new_instance(instances, tmp_path)
        conn.repoint(second.address("tcp"))
        await asyncio.wait_for(sender, 30)
        await until_async(
            "len(set(first.taken) | set(second.taken)) >= n",
            lambda: len(set(first.taken) | set(second.taken)),
            lambda v: v >= n,
            within=20,
        )
        assert set(first.taken) | set(second.taken) == set(range(1, n + 1))
        assert sorted(second.taken) == second.taken  # in order
    finally:
        sender.cancel()
        await conn.close(linger=0.5)


async def test_a_reconnect_to_the_same_instance_replays_without_duplicates(
    instances: list[Instance], tmp_path: Path
) -> None:
    n = 3000
    inst = await new_instance(instances, tmp_path)
    conn = Connection("c", inst.address("tcp"), "in", "cam.out", make_policy("fifo", 64, "block"))
    conn.start()
    sender = asyncio.create_task(publish(conn, n, every=10))
    try:
        for k in range(3):
            await until_async(
                f"more than {(k + 1) * 300} taken",
                lambda: len(inst.taken),
                lambda v, goal=(k + 1) * 300: v > goal,  # type: ignore[misc]
            )
            await inst.deactivate()  # frames arriving now are delivered, not taken
            await until_async("conn.unacked > 0", lambda: conn.unacked, lambda v: v > 0)
            for receiver in list(inst.server._receivers):
                receiver.abort()  # the network broke; the instance lives on
            await until_async(
                f"reconnect {k + 1}",
                lambda: conn.reconnects,
                lambda v, k=k: v > k,  # type: ignore[misc]
                within=10,
            )
            inst.resume()
        await asyncio.wait_for(sender, 30)
        await until_async(
            "len(inst.taken) >= n", lambda: len(inst.taken), lambda v: v >= n, within=20
        )
        assert inst.taken == list(range(1, n + 1))
        assert conn.replayed > 0
    finally:
        sender.cancel()
        await conn.close(linger=0.5)


async def test_the_window_stops_the_sender_until_frames_are_taken(
    instances: list[Instance], tmp_path: Path
) -> None:
    inst = await new_instance(instances, tmp_path, consume=False)
    policy = make_policy("fifo", 10, "block")
    conn = Connection("c", inst.address("tcp"), "in", "cam.out", policy, window=(50, 1 << 20))
    conn.start()
    sender = asyncio.create_task(publish(conn, 500))
    try:
        held = lambda: (conn.seq, conn.unacked, conn.pending, sender.done())  # noqa: E731
        # 50 sent and unacked, 10 more queued behind the window, the publisher blocked ...
        await until_async("the window full", held, lambda seen: seen == (50, 50, 10, False))
        await stays_async(  # ... and so it stays while nothing is taken
            "the sender held at the window",
            held,
            lambda seen: seen == (50, 50, 10, False),
            window=0.1,
        )
        inst.resume()
        await asyncio.wait_for(sender, 10)
        await until_async("len(inst.taken) == 500", lambda: len(inst.taken), lambda v: v == 500)
        assert inst.taken == list(range(1, 501))
    finally:
        sender.cancel()
        await conn.close(linger=0.5)


async def test_a_receiver_that_does_not_acknowledge_gets_a_plain_stream(tmp_path: Path) -> None:
    port = RecordingPort()  # no attach_stream
    server = DataServer(lambda name: port)
    await server.start()
    conn = Connection(
        "c", f"tcp://{server.addresses['tcp']}", "in", "o.p", make_policy("fifo", 100)
    )
    conn.start()
    try:
        await asyncio.wait_for(conn.wait_connected(), 5)
        for value in range(20):
            assert conn.offer(value)
        await until_async("len(port.frames) == 20", lambda: len(port.frames), lambda v: v == 20)
        assert conn.unacked == 0
        assert server.counters["acked"] == 0
    finally:
        await conn.close()
        await server.close()


# ---- the connection's policy at the receiver, and its drops told back -----------------------


async def five_thousand_into_a_stalled_port(
    tmp_path: Path, kind: str, given: dict[str, object] | None
) -> tuple[Connection, InPortRuntime, list[int]]:
    """The issue's silent-loss case: a fast producer sends 5,000 small frames into an InPort
    whose class declares the defaults (all, 8, overwrite) and whose component takes nothing
    until the producer is done, then everything that waits."""
    port = InPortRuntime("in", ConnectorPolicy())
    server = DataServer(lambda name: port if name == "in" else None, unix_path=str(tmp_path / "s"))
    await server.start()
    address = f"{kind}://{server.addresses[kind]}"
    policy = ConnectorPolicy.from_map(given)
    conn = Connection("c", address, "in", "cam.out", policy, given=given)
    conn.start()
    taken: list[int] = []
    try:
        await until_async("connected", lambda: conn.connected, bool)
        for value in range(1, 5001):
            while not conn.offer(value):
                await conn.drain()
            if value % 100 == 0:
                await asyncio.sleep(0)
        if given is not None:  # block at the port: every frame waits there, take them all
            while len(taken) < 5000:
                taken.append(await asyncio.wait_for(port.get(), 10))
        await until_async(
            "everything the sender wrote arrived",
            lambda: (conn.pending, conn.seq, port.frames_in),
            lambda s: s[0] == 0 and s[1] == s[2],
            within=20,
        )
        while port.qsize():
            taken.append(port.get_nowait())
        await until_async(
            "the last acknowledgement",
            lambda: conn.unacked,
            lambda n: n == 0,
            within=10,
        )
    finally:
        await conn.close()
        await server.close()
    return conn, port, taken


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_frames_a_receiving_inport_discards_are_counted_at_the_sender(
    tmp_path: Path, kind: str
) -> None:
    conn, port, taken = await five_thousand_into_a_stalled_port(tmp_path, kind, None)
    assert taken == list(range(4993, 5001))  # the newest 8 (both queues overwrite)
    assert port.dropped > 0  # the port's default (overwrite 8) threw frames away
    assert conn.dropped_remote == port.dropped  # and its acknowledgements told the sender
    assert conn.dropped + conn.dropped_remote == 5000 - 8  # every lost frame counted there


@pytest.mark.parametrize("kind", ["tcp", "unix"])
async def test_a_connections_policy_reaches_the_receiving_inport(tmp_path: Path, kind: str) -> None:
    """`full: block, buffer: 64` on the connection (a system file's `policy:`) rules the
    receiving InPort too, over the class's overwrite: nothing is evicted (the frames wait at the
    port, bounded by the sender's window of unacknowledged frames, not by `buffer`)."""
    given: dict[str, object] = {"full": "block", "buffer": 64}
    conn, port, taken = await five_thousand_into_a_stalled_port(tmp_path, kind, given)
    assert taken == list(range(1, 5001))
    assert port.policy_for("c") == ConnectorPolicy(buffer=64, full="block")
    assert (port.dropped, conn.dropped, conn.dropped_remote) == (0, 0, 0)


def test_the_receiver_takes_only_buffer_and_full_from_a_connection() -> None:
    """`push` and `skip` are the sender's (applied there, not twice); `full: block` holds only for
    an acknowledged stream, whose sender's window bounds the queue."""
    port = InPortRuntime("in", ConnectorPolicy("new", 4, "drop"))
    given: dict[str, object] = {"push": "skip", "skip": 2, "buffer": 3, "full": "block"}
    assert port.connection_policy(given) == ConnectorPolicy("new", 3, "block")
    assert port.connection_policy(given, acked=False) == ConnectorPolicy("new", 3, "drop")
    assert port.connection_policy({}) == port.policy
    with pytest.raises(ValueError, match="push"):
        port.connection_policy({"push": "later"})  # every key is still checked
