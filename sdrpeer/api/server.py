"""Serving the API app: bind, report the URL actually bound, stop; which connections it keeps.

How it works: a `GuardedSite` listens like aiohttp's `TCPSite`, but every accepted connection
goes through a `ConnectionTable` (`sdrpeer.api.connections`, the rules: at most
`max_connections`, the idlest connection of the address holding the most shed to make room for
a newcomer, an idle deadline and a request-head deadline). This module is its shell: each
connection's protocol (`_Guarded`) tells the table when it opens, receives bytes and closes, and
makes aiohttp's request handler only once bytes arrive; a middleware tells it when a request is
being served; one timer, re-armed when the table's next deadline changes, closes what has
expired. The listening socket accepts `accept_batch` connections per event-loop turn while the
kernel queues up to `backlog` (`sdrpeer.api.config`). aiohttp's own keep-alive timeout stays as
a backstop only (twice the idle deadline). A robot is a small computer: whoever can reach the
API must not be able to hold every file descriptor of the agent, nor keep the robot's own tools
and the other agents from being answered.
"""

from __future__ import annotations

import asyncio
import os
import socket
from collections.abc import Iterable
from typing import Any, cast

from aiohttp import web

from sdrpeer.api.app import Handler, Route, build_app
from sdrpeer.api.config import ApiLimits
from sdrpeer.api.connections import ConnectionTable
from sdrpeer.api.view import AgentView


class _Guarded(asyncio.Protocol):
    """One API connection: aiohttp's request handler, with the site's table told what happens.
    The handler (its parser, its task, its timer) is made when the first bytes arrive: a
    connection that sends nothing costs its socket and a table entry, nothing more."""

    def __init__(self, guard: ConnectionGuard, server: web.Server) -> None:
        self._guard, self._server = guard, server
        self._handler: asyncio.Protocol | None = None
        self._transport: asyncio.Transport | None = None
        self._kept = False

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = cast(asyncio.Transport, transport)
        self._kept = self._guard.admit(self._transport)

    def data_received(self, data: bytes) -> None:
        if not self._kept:
            return
        assert self._transport is not None
        self._guard.received(self._transport)
        if self._handler is None:
            self._handler = self._server()
            self._handler.connection_made(self._transport)
        self._handler.data_received(data)

    def eof_received(self) -> bool | None:
        return None if self._handler is None else self._handler.eof_received()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._transport is not None:
            self._guard.lost(self._transport)
        if self._handler is not None:
            self._handler.connection_lost(exc)

    def pause_writing(self) -> None:
        if self._handler is not None:
            self._handler.pause_writing()

    def resume_writing(self) -> None:
        if self._handler is not None:
            self._handler.resume_writing()


class ConnectionGuard:
    """The shell around a `ConnectionTable`: told what happens on each connection, it closes
    what the table says, and keeps one timer armed at the table's next deadline."""

    def __init__(self, limits: ApiLimits) -> None:
        self.table: ConnectionTable[asyncio.Transport] = ConnectionTable(limits)
        """The connections kept, and why others were closed (`table.counters`)."""
        self._timer: asyncio.TimerHandle | None = None
        self._armed: float | None = None
        self._stopped = False

    def admit(self, transport: asyncio.Transport) -> bool:
        """A connection was accepted: whether it is kept (the table may close another)."""
        peer = transport.get_extra_info("peername")
        addr = str(peer[0]) if isinstance(peer, tuple) and peer else "?"
        closing = self.table.open(transport, addr, _now())
        for other in closing:
            other.close()
        self._rearm()
        return transport not in closing

    def received(self, transport: asyncio.Transport) -> None:
        """Bytes arrived on a connection."""
        self.table.received(transport, _now())
        self._rearm()

    def lost(self, transport: asyncio.Transport) -> None:
        """A connection is closed."""
        self.table.closed(transport)
        self._rearm()

    @web.middleware
    async def middleware(self, request: web.Request, handler: Handler) -> web.StreamResponse:
        """Marks the request's connection busy while its handler runs (never shed or timed
        out then)."""
        transport = request.transport
        if not isinstance(transport, asyncio.Transport):
            return await handler(request)
        self.table.started(transport)
        self._rearm()
        try:
            return await handler(request)
        finally:
            self.table.finished(transport, _now())
            self._rearm()

    def stop(self) -> None:
        """The site stopped: disarm the timer for good and close every waiting connection (one
        that never sent a byte has no aiohttp handler for the runner's shutdown to close; busy
        ones are the runner's to finish)."""
        self._stopped = True
        if self._timer is not None:
            self._timer.cancel()
        self._timer = self._armed = None
        for transport in self.table:
            if self.table.state(transport) != "busy":
                self.table.closed(transport)
                transport.close()

    def _rearm(self) -> None:
        deadline = self.table.next_deadline()
        if deadline == self._armed or self._stopped:
            return
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        self._armed = deadline
        if deadline is not None:
            self._timer = asyncio.get_running_loop().call_at(deadline, self._on_timer)

    def _on_timer(self) -> None:
        self._timer = self._armed = None
        for transport in self.table.expired(_now()):
            transport.close()
        self._rearm()


def _now() -> float:
    return asyncio.get_running_loop().time()


class GuardedSite(web.BaseSite):
    """A TCP site whose connections are kept, shed and timed out by a `ConnectionGuard`."""

    def __init__(
        self, runner: web.BaseRunner, host: str, port: int, guard: ConnectionGuard
    ) -> None:
        super().__init__(runner, backlog=guard.table.limits.backlog)
        self._host, self._port, self.guard = host, port, guard
        self.port = port
        """The port bound (after `start`)."""

    @property
    def table(self) -> ConnectionTable[asyncio.Transport]:
        """The connections kept, and why others were closed (`table.counters`)."""
        return self.guard.table

    @property
    def refused(self) -> int:
        """Connections closed at accept because every kept connection was busy."""
        return self.guard.table.counters["refused"]

    def open_connections(self) -> int:
        """The connections kept open now."""
        return len(self.guard.table)

    def connections_with_handler(self) -> int:
        """The connections that have an aiohttp request handler (they have sent bytes)."""
        server = self._runner.server
        return 0 if server is None else len(server.connections)

    @property
    def name(self) -> str:
        return f"http://{self._host}:{self.port}"

    async def start(self) -> None:
        await super().start()
        server = self._runner.server
        assert server is not None
        guard = self.guard
        self._server = await asyncio.get_running_loop().create_server(
            lambda: _Guarded(guard, server),
            self._host,
            self._port,
            backlog=guard.table.limits.accept_batch,
            reuse_address=True,
        )
        for listening in self._server.sockets:  # the kernel's queue: longer than one batch
            with socket.socket(fileno=os.dup(listening.fileno())) as same:
                same.listen(self._backlog)
        self.port = self._server.sockets[0].getsockname()[1]

    async def stop(self) -> None:
        self.guard.stop()
        await super().stop()


async def serve_api(
    view: AgentView,
    token: str,
    host: str,
    port: int,
    *,
    extra_routes: Iterable[Route] = (),
    peer_tokens: list[str] | None = None,
    limits: ApiLimits | None = None,
) -> tuple[web.AppRunner, GuardedSite]:
    """Start the API on host:port (0 picks a free port); returns the runner and the site (its
    `name` is the base URL bound)."""
    limits = limits or ApiLimits()
    app = build_app(view, token=token, extra_routes=extra_routes, peer_tokens=peer_tokens)
    guard = ConnectionGuard(limits)
    app.middlewares.insert(0, cast(Any, guard.middleware))
    runner = web.AppRunner(app, access_log=None, keepalive_timeout=2 * limits.idle_timeout)
    await runner.setup()
    site = GuardedSite(runner, host, port, guard)
    await site.start()
    return runner, site
