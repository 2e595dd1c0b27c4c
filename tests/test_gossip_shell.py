"""The UDP shell around the membership core, on a real loopback socket in this process, with an
injected wall clock: which stale datagrams get an answer (the clock nudge), and to whom."""

from __future__ import annotations

import asyncio
import random
import socket
from collections.abc import AsyncIterator, Callable, Iterator
from contextlib import ExitStack, asynccontextmanager

import pytest

from sdrpeer.errors import WireError
from sdrpeer.gossip.config import lan
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.messages import Addr, Gossip
from sdrpeer.gossip.udp_shell import GossipShell, open_gossip
from sdrpeer.gossip.wire import Codec, Keyring

T = 1_700_000_000.0
KEY = bytes(range(32))


class Wall:
    """A wall clock the test sets."""

    def __init__(self, now: float) -> None:
        self.now = now

    def __call__(self) -> float:
        """The time it was set to."""
        return self.now


@asynccontextmanager
async def robot_b(wall: Wall) -> AsyncIterator[tuple[GossipShell, Addr]]:
    """Robot "b": a shell on 127.0.0.1 driving a core with no peers (it sends nothing itself)."""
    codec = Codec("b", Keyring([KEY]), seq_start=1)
    shell, addr = await open_gossip("127.0.0.1", 0, codec, lambda _: None, wall=wall)
    loop = asyncio.get_running_loop()
    shell.attach(Membership("b", addr, lan(), now=loop.time(), rng=random.Random(1)))
    try:
        yield shell, addr
    finally:
        shell.close()


def udp_sockets(stack: ExitStack, n: int) -> Iterator[socket.socket]:
    """`n` non-blocking UDP sockets on 127.0.0.1 (as many source addresses), closed with `stack`."""
    for _ in range(n):
        sock = stack.enter_context(socket.socket(socket.AF_INET, socket.SOCK_DGRAM))
        sock.bind(("127.0.0.1", 0))
        sock.setblocking(False)
        yield sock


async def until(what: str, ok: Callable[[], bool]) -> None:
    """Wait (at most 5 s, polling every 10 ms) until `ok()`."""
    async with asyncio.timeout(5.0):
        while not ok():  # noqa: ASYNC110 - counters have no event to wait on
            await asyncio.sleep(0.01)
    assert ok(), what


async def test_a_stale_replay_gets_no_answer_whatever_its_source_address() -> None:
    """Issue 30: a datagram recorded 36 s ago and replayed from five source addresses used to
    get one empty gossip back per address. What followed it from its sender was accepted since,
    so it cannot come from a robot whose clock is behind: no answer, from any address."""
    wall = Wall(T + 5)
    a = Codec("a", Keyring([KEY]), seq_start=1)
    recorded = a.encode(Gossip("a", (), "b"), T)
    later = a.encode(Gossip("a", (), "b"), T + 5)
    async with robot_b(wall) as (shell, addr):
        with ExitStack() as stack:
            first, *spoofed = udp_sockets(stack, 6)
            first.sendto(later, addr)
            await until("b takes a's datagram", lambda: shell.codec.counters["accepted"] == 1)
            wall.now = T + 36
            for sock in spoofed:
                sock.sendto(recorded, addr)
            await until("five stale refusals", lambda: shell.codec.counters["stale"] == 5)
            assert shell.counters["clock_nudges"] == 0


async def test_a_sender_behind_is_answered_once_per_sender_and_only_it_can_open_the_answer() -> (
    None
):
    """A robot whose clock is behind (its datagrams stale but newer than any before) gets one
    empty gossip, addressed to it by name, whatever address it sends from next within 5 s."""
    wall = Wall(T + 40)
    a = Codec("a", Keyring([KEY]), seq_start=1)
    async with robot_b(wall) as (shell, addr):
        with ExitStack() as stack:
            one, two = udp_sockets(stack, 2)
            one.sendto(a.encode(Gossip("a", (), "b"), T), addr)
            await until("a's first stale datagram", lambda: shell.codec.counters["stale"] == 1)
            two.sendto(a.encode(Gossip("a", (), "b"), T + 1), addr)
            await until("a's second stale datagram", lambda: shell.codec.counters["stale"] == 2)
            assert shell.counters["clock_nudges"] == 1
            loop = asyncio.get_running_loop()
            async with asyncio.timeout(5.0):
                answer = await loop.sock_recv(one, 65535)
    with pytest.raises(WireError) as refused:
        Codec("c", Keyring([KEY])).decode(answer, T + 1)
    assert refused.value.reason == "wrong_receiver"
    assert a.decode(answer, T + 1) == Gossip("b", (), "a")
    assert a.clock.offset_ms == 39_000  # a, 39 s behind, adopted b's time from it
