"""The API's listening socket: connections beyond the limit are closed at accept, idle ones are
closed by the server (before their first request and between two), and it serves on after."""

from __future__ import annotations

import asyncio

from sdrpeer.api.server import serve_api
from tests.test_api import FakeView
from tests.wait import until_async


async def closed_by_server(reader: asyncio.StreamReader, within: float = 20.0) -> bool:
    """Whether the server closes this connection (EOF) within `within` seconds."""
    try:
        async with asyncio.timeout(within):
            await reader.read()  # to EOF
    except TimeoutError:
        return False
    return True


async def test_excess_and_idle_connections_are_closed_and_the_api_serves_on() -> None:
    runner, site = await serve_api(
        FakeView(), "t" * 32, "127.0.0.1", 0, max_connections=4, idle_timeout=0.5
    )
    try:
        held = [await asyncio.open_connection("127.0.0.1", site.port) for _ in range(4)]
        await until_async("four connections", lambda: len(site.connections()), lambda n: n >= 4)
        extra = [await asyncio.open_connection("127.0.0.1", site.port) for _ in range(2)]
        for reader, _ in extra:
            async with asyncio.timeout(20):
                assert await reader.read() == b""  # over the limit: closed at once, unanswered
        assert site.refused == 2
        for reader, _ in held:  # never sent a byte: closed once idle
            assert await closed_by_server(reader)
        reader, writer = await asyncio.open_connection("127.0.0.1", site.port)
        writer.write(b"GET /healthz HTTP/1.1\r\nHost: x\r\n\r\n")
        await writer.drain()
        status = await reader.readline()
        assert status.startswith(b"HTTP/1.1 200"), status
        assert await closed_by_server(reader)  # idle after its request: closed too
        for _, w in [*held, *extra, (reader, writer)]:
            w.close()
    finally:
        await runner.cleanup()
