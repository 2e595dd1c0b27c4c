"""Each connector policy on a slow receiver: which frames wait, which are dropped, who blocks.

A `StalledReceiver` stops reading after the hello; fillers are offered until the socket and the
transport's buffer are full and frames stay pending; then markers show what the policy keeps.
"""

from __future__ import annotations

import asyncio
from pathlib import Path

import pytest

from sdrpeer.dataplane import Connection
from sdrpeer.dataplane.testing import RecordingPort, StalledReceiver, make_policy
from tests.wait import stays_async, until_async

FILLER = b"f" * 256 * 1024


async def stalled(
    tmp_path: Path, push: str, buffer: int, full: str, skip: int = 0
) -> tuple[StalledReceiver, Connection]:
    rx = StalledReceiver()
    to = await rx.start(str(tmp_path / "slow.sock"))
    conn = Connection("slow", to, "in", "a.b", make_policy(push, buffer, full, skip))
    conn.start()
    async with asyncio.timeout(5):
        await conn.wait_connected()
    for _ in range(400):  # fill the socket until frames stay pending
        conn.offer(FILLER)
        await asyncio.sleep(0.002)
        if conn.pending:
            await asyncio.sleep(0.05)
            if conn.pending:
                for _ in range(buffer):  # fill the queue too
                    conn.offer(FILLER)
                return rx, conn
    raise AssertionError("the stalled receiver never filled up")


def markers(port: RecordingPort) -> list[int]:
    return [v for v in port.values if isinstance(v, int)]


async def finish(rx: StalledReceiver, conn: Connection) -> None:
    rx.release()
    await until_async("conn.pending == 0", lambda: conn.pending, lambda v: v == 0)
    await until_async(
        "len(rx.port.frames) == conn.frames_out",
        lambda: len(rx.port.frames),
        lambda v: v == conn.frames_out,
    )
    assert rx.port.seqs == list(range(1, conn.seq + 1))  # seqs number what was written
    await conn.close()
    await rx.close()


async def test_overwrite_keeps_the_newest(tmp_path: Path) -> None:
    rx, conn = await stalled(tmp_path, "fifo", 4, "overwrite")
    dropped = conn.dropped
    accepted = [conn.offer(i) for i in range(1, 11)]
    assert accepted == [True] * 10
    assert conn.pending == 4
    assert conn.dropped - dropped == 10  # 4 fillers and 6 markers evicted
    await finish(rx, conn)
    assert markers(rx.port) == [7, 8, 9, 10]


async def test_drop_refuses_the_newest(tmp_path: Path) -> None:
    rx, conn = await stalled(tmp_path, "all", 4, "drop")
    dropped = conn.dropped
    accepted = [conn.offer(i) for i in range(1, 11)]
    assert accepted == [False] * 10
    assert conn.dropped - dropped == 10
    await finish(rx, conn)
    assert markers(rx.port) == []


async def test_block_makes_the_sender_wait(tmp_path: Path) -> None:
    rx, conn = await stalled(tmp_path, "fifo", 4, "block")
    assert conn.dropped == 0
    assert not conn.offer(1)  # full: not queued, not dropped
    drain = asyncio.create_task(conn.drain())
    # still blocked while the receiver reads nothing
    await stays_async("drain blocked", drain.done, lambda done: not done, window=0.05)
    rx.release()
    async with asyncio.timeout(5):
        await drain
    assert conn.offer(1)
    await finish(rx, conn)
    assert markers(rx.port) == [1]
    assert conn.dropped == 0


async def test_new_keeps_only_the_newest(tmp_path: Path) -> None:
    rx, conn = await stalled(tmp_path, "new", 8, "overwrite")
    assert conn.pending == 1
    for i in range(1, 11):
        conn.offer(i)
    assert conn.pending == 1
    await finish(rx, conn)
    assert markers(rx.port) == [10]


@pytest.mark.parametrize(("skip", "sent"), [(0, list(range(1, 13))), (2, [1, 4, 7, 10])])
async def test_skip_sends_every_skip_plus_one(tmp_path: Path, skip: int, sent: list[int]) -> None:
    rx = StalledReceiver()
    to = await rx.start(str(tmp_path / "skip.sock"))
    conn = Connection("skip", to, "in", "a.b", make_policy("skip", 64, "block", skip))
    conn.start()
    accepted = [conn.offer(i) for i in range(1, 13)]
    assert accepted == [i in sent for i in range(1, 13)]
    await finish(rx, conn)
    assert markers(rx.port) == sent
