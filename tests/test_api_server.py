"""The API's listening socket under floods (sdrpeer.api.server with sdrpeer.api.connections): a
caller is answered while a flood holds every connection the API keeps, excess connections shed
the oldest waiting one (a busy one never), idle and half-sent connections are closed on their
deadlines, and the API serves on after."""

from __future__ import annotations

import asyncio
import sys
from collections.abc import AsyncIterator
from contextlib import asynccontextmanager
from pathlib import Path

from aiohttp import web

from sdrpeer.api.app import Route
from sdrpeer.api.config import ApiLimits
from sdrpeer.api.server import GuardedSite, serve_api
from sdrpeer.client import AgentClient
from tests.test_api import FakeView
from tests.wait import until_async

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))

from bench_api_flood import HEAD_START, Flood, raise_fd_limit

TOKEN = "t" * 32


async def closed_by_server(reader: asyncio.StreamReader, within: float = 20.0) -> bool:
    """Whether the server closes this connection (EOF) within `within` seconds."""
    try:
        async with asyncio.timeout(within):
            await reader.read()  # to EOF
    except TimeoutError:
        return False
    except ConnectionError:
        return True
    return True


async def members_status(port: int) -> int | str:
    """`GET /v1/members` as the command line makes it (sdrpeer.client, in a thread: connect and
    send at once): 200, another status, or why it failed."""
    client = AgentClient(f"http://127.0.0.1:{port}", timeout=5.0)
    try:
        await asyncio.to_thread(client.get, "/v1/members")
    except Exception as exc:  # the failure is the finding: say which
        return f"{type(exc).__name__}: {exc}"
    return 200


async def get(port: int, path: str) -> tuple[asyncio.StreamReader, asyncio.StreamWriter]:
    """A connection that has sent `GET path` (keep-alive) and not read the answer."""
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    writer.write(f"GET {path} HTTP/1.1\r\nHost: x\r\n\r\n".encode())
    await writer.drain()
    return reader, writer


@asynccontextmanager
async def flooding(port: int, flood: Flood) -> AsyncIterator[Flood]:
    """`flood` running against 127.0.0.1:port until the block ends."""
    stop = asyncio.Event()
    task = asyncio.create_task(flood.run(stop))
    try:
        yield flood
    finally:
        stop.set()
        async with asyncio.timeout(30):
            await task


async def test_the_robot_is_answered_while_a_flood_holds_every_connection() -> None:
    """Fails on the old code: the flood held the 256 connections the API keeps, and the
    caller's connection was closed at accept (refused) with the flood's excess. Observed from
    the flood's side only, so the test runs on either code."""
    raise_fd_limit(2048)
    runner, site = await serve_api(FakeView(), TOKEN, "127.0.0.1", 0)
    # 8 connects at a time: a burst over the old code's 128-long accept queue waited for SYN-ACK
    # retransmissions (1, 2, 4 s ...) before it was accepted, and refused
    flood = Flood("127.0.0.1", site.port, 300, byte_interval=0.2, reopen=False, opening=8)
    try:
        async with flooding(site.port, flood):
            await until_async("300 opened, 44 closed", lambda: flood.counts, full)
            for _ in range(5):
                assert await members_status(site.port) == 200
                assert flood.held >= 255  # the flood still holds the rest
        assert site.table.counters["shed"] >= 44 + 1  # its excess, then room for the first call
        assert site.refused == 0
    finally:
        await runner.cleanup()


def full(counts: dict[str, int]) -> bool:
    """Whether a 300-connection flood has opened all and the API closed the 44 over 256."""
    return counts["opened"] >= 300 and counts["closed_by_server"] >= 300 - 256


async def test_a_flood_that_reopens_what_is_shed_does_not_shed_a_caller_unread() -> None:
    """The flood opens again every connection the API closes, so the API accepts (and sheds)
    in bursts all the time: each caller's request is still read and answered."""
    raise_fd_limit(2048)
    runner, site = await serve_api(FakeView(), TOKEN, "127.0.0.1", 0)
    flood = Flood("127.0.0.1", site.port, 600, byte_interval=0.2, max_opens=20_000)
    try:
        async with flooding(site.port, flood):
            await until_async(
                "the flood opened", lambda: flood.counts["opened"], lambda n: n >= 600
            )
            answers = []
            for _ in range(10):
                answers.append(await members_status(site.port))
            churned = site.table.counters["shed"]
        assert answers == [200] * 10
        assert churned > 600  # the flood was reopening while the calls were made
    finally:
        await runner.cleanup()


async def test_a_flood_from_one_address_sheds_its_own_connections_not_another_addresss() -> None:
    """A flood from 127.0.0.2 (another host) fills the table; a caller from 127.0.0.1 is answered
    and its keep-alive connection, soon the oldest of all, outlives the flood's growth. Fails on
    the old code (the caller was refused at accept)."""
    runner, site = await serve_api(
        FakeView(), TOKEN, "127.0.0.1", 0, limits=ApiLimits(max_connections=16)
    )
    first = Flood("127.0.0.1", site.port, 16, reopen=False, byte_interval=0.2, source="127.0.0.2")
    more = Flood("127.0.0.1", site.port, 32, reopen=False, byte_interval=0.2, source="127.0.0.2")
    try:
        async with flooding(site.port, first):
            await until_async("the API full", site.open_connections, lambda n: n >= 16)
            reader, writer = await get(site.port, "/healthz")  # keep-alive, from 127.0.0.1
            assert (await reader.readuntil(b"\r\n\r\n")).startswith(b"HTTP/1.1 200")
            await reader.readuntil(b"}")  # the JSON body; the connection waits for another request
            async with flooding(site.port, more):
                await until_async(
                    "32 more opened", lambda: more.counts["opened"], lambda n: n >= 32
                )
                await until_async("shed 33", lambda: site.table.counters["shed"], lambda n: n >= 33)
                writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
                assert (await reader.readuntil(b"\r\n\r\n")).startswith(b"HTTP/1.1 200")
            writer.close()
    finally:
        await runner.cleanup()


async def test_excess_connections_shed_the_oldest_waiting_one_never_a_busy_one() -> None:
    release = asyncio.Event()

    async def slow(request: web.Request) -> web.Response:
        async with asyncio.timeout(30):
            await release.wait()
        return web.json_response({"slow": True})

    limits = ApiLimits(max_connections=2)
    runner, site = await serve_api(
        FakeView(), TOKEN, "127.0.0.1", 0, extra_routes=[Route("GET", "/slow", slow)], limits=limits
    )
    try:
        busy_reader, busy = await get(site.port, "/slow")
        idle_reader, idle = await asyncio.open_connection("127.0.0.1", site.port)
        await until_async("both kept", lambda: states(site), lambda s: s == ["busy", "idle"])
        new_reader, new = await get(site.port, "/healthz")  # makes room: the idle one goes
        assert await closed_by_server(idle_reader)
        assert (await new_reader.readline()).startswith(b"HTTP/1.1 200")
        assert site.table.counters["shed"] == 1
        slow2_reader, slow2 = await get(site.port, "/slow")  # sheds `new`, waiting again
        await until_async("both busy", lambda: states(site), lambda s: s == ["busy", "busy"])
        refused_reader, refused = await asyncio.open_connection("127.0.0.1", site.port)
        assert await closed_by_server(refused_reader)  # every kept connection is busy
        assert site.refused == 1
        release.set()
        for reader in (busy_reader, slow2_reader):
            assert (await reader.readline()).startswith(b"HTTP/1.1 200")
        for writer in (busy, idle, new, slow2, refused):
            writer.close()
    finally:
        await runner.cleanup()


def states(site: GuardedSite) -> list[str]:
    """The kept connections' states, sorted."""
    return sorted(str(site.table.state(key)) for key in site.table)


async def test_a_half_sent_head_and_an_idle_connection_are_closed_on_their_deadlines() -> None:
    runner, site = await serve_api(
        FakeView(),
        TOKEN,
        "127.0.0.1",
        0,
        limits=ApiLimits(max_connections=8, idle_timeout=1.5, header_timeout=0.3),
    )
    try:
        idle_reader, idle = await asyncio.open_connection("127.0.0.1", site.port)
        slow_reader, slow = await asyncio.open_connection("127.0.0.1", site.port)
        slow.write(HEAD_START)
        closed = False
        for _ in range(200):  # a byte every 0.05 s: never quiet, but its head never ends
            try:
                async with asyncio.timeout(0.05):
                    closed = await slow_reader.read(1) == b""
            except TimeoutError:
                slow.write(b"a")
            except ConnectionError:
                closed = True
            if closed:
                break
        assert closed
        assert site.table.counters == {
            "refused": 0,
            "shed": 0,
            "idle_closed": 0,
            "header_closed": 1,
        }
        assert await closed_by_server(idle_reader)  # sent nothing: closed once idle
        assert site.table.counters["idle_closed"] == 1
        reader, writer = await get(site.port, "/healthz")
        assert (await reader.readline()).startswith(b"HTTP/1.1 200")
        assert await closed_by_server(reader)  # idle after its request: closed too
        assert site.table.counters["idle_closed"] == 2
        for w in (idle, slow, writer):
            w.close()
    finally:
        await runner.cleanup()


async def test_stopping_the_api_closes_connections_that_never_sent_a_byte() -> None:
    """A connection that sends nothing has no aiohttp handler (it costs a socket and a table
    entry): stopping the API must close it all the same."""
    runner, site = await serve_api(FakeView(), TOKEN, "127.0.0.1", 0)
    reader, writer = await asyncio.open_connection("127.0.0.1", site.port)
    await until_async("kept", site.open_connections, lambda n: n == 1)
    assert site.connections_with_handler() == 0
    await runner.cleanup()
    assert await closed_by_server(reader)
    assert site.open_connections() == 0
    writer.close()


async def test_a_malformed_head_is_answered_400_and_forgotten() -> None:
    """Garbage on a kept connection reaches aiohttp's parser through the table's wrapper: a 400,
    the connection closed and forgotten, and the API serves on."""
    runner, site = await serve_api(FakeView(), TOKEN, "127.0.0.1", 0)
    try:
        reader, writer = await asyncio.open_connection("127.0.0.1", site.port)
        writer.write(b"\x00\xff NOT HTTP \x01\r\n\r\n")
        assert (await reader.readline()).split(b" ")[1] == b"400"  # aiohttp answers HTTP/1.0
        assert await closed_by_server(reader)
        await until_async("forgotten", site.open_connections, lambda n: n == 0)
        assert await members_status(site.port) == 200
        writer.close()
    finally:
        await runner.cleanup()
