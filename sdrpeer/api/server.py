"""Serving the API app: bind, report the URL actually bound, stop; idle and excess connections.

How it works: a `BoundedSite` listens like aiohttp's `TCPSite`, except that a connection beyond
`MAX_CONNECTIONS` open at once is closed as soon as it is accepted (counted in `refused`), and
every connection idle for `IDLE_TIMEOUT` seconds (before its first request or between two) is
closed by the server (aiohttp's keep-alive timeout, an hour by default). A long request (the
dashboard's event stream) is not idle. A robot is a small computer: without both, whoever can
reach the API could hold every file descriptor of the agent with idle connections.
"""

from __future__ import annotations

import asyncio
from collections.abc import Iterable

from aiohttp import web

from sdrpeer.api.app import Route, build_app
from sdrpeer.api.view import AgentView

MAX_CONNECTIONS = 256
"""Connections the API keeps open at once (the agent's other sockets need descriptors too)."""

IDLE_TIMEOUT = 30.0
"""Seconds an API connection may stay idle (no request in progress) before it is closed: longer
than aiohttp clients (agents' peer calls) keep an idle connection (15 s), so a client never
reuses one the server is closing."""


class _Refuse(asyncio.Protocol):
    """A connection over the limit: closed at once."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        transport.close()


class BoundedSite(web.BaseSite):
    """A TCP site that refuses connections beyond `limit` open at once."""

    def __init__(
        self, runner: web.BaseRunner, host: str, port: int, limit: int = MAX_CONNECTIONS
    ) -> None:
        super().__init__(runner)
        self._host, self._port, self.limit = host, port, limit
        self.refused = 0
        """Connections closed at accept because `limit` were open."""
        self.port = port
        """The port bound (after `start`)."""

    def connections(self) -> list[object]:
        """The connections open now."""
        server = self._runner.server
        return [] if server is None else list(server.connections)

    @property
    def name(self) -> str:
        return f"http://{self._host}:{self.port}"

    async def start(self) -> None:
        await super().start()
        server = self._runner.server
        assert server is not None

        def protocol() -> asyncio.Protocol:
            if len(server.connections) >= self.limit:
                self.refused += 1
                return _Refuse()
            return server()

        self._server = await asyncio.get_running_loop().create_server(
            protocol, self._host, self._port, backlog=self._backlog, reuse_address=True
        )
        self.port = self._server.sockets[0].getsockname()[1]


async def serve_api(
    view: AgentView,
    token: str,
    host: str,
    port: int,
    *,
    extra_routes: Iterable[Route] = (),
    peer_tokens: list[str] | None = None,
    max_connections: int = MAX_CONNECTIONS,
    idle_timeout: float = IDLE_TIMEOUT,
) -> tuple[web.AppRunner, BoundedSite]:
    """Start the API on host:port (0 picks a free port); returns the runner and the site (its
    `name` is the base URL bound)."""
    app = build_app(view, token=token, extra_routes=extra_routes, peer_tokens=peer_tokens)
    runner = web.AppRunner(app, access_log=None, keepalive_timeout=idle_timeout)
    await runner.setup()
    site = BoundedSite(runner, host, port, max_connections)
    await site.start()
    return runner, site
