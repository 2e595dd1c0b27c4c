"""Serving the API app: bind, report the URL actually bound, stop."""

from __future__ import annotations

import asyncio
from collections.abc import Iterable

from aiohttp import web

from sdrpeer.api.app import Route, build_app
from sdrpeer.api.view import AgentView


async def serve_api(
    view: AgentView,
    token: str,
    host: str,
    port: int,
    *,
    extra_routes: Iterable[Route] = (),
    peer_tokens: list[str] | None = None,
) -> tuple[web.AppRunner, str]:
    """Start the API on host:port (0 picks a free port); returns the runner and the base URL."""
    app = build_app(view, token=token, extra_routes=extra_routes, peer_tokens=peer_tokens)
    runner = web.AppRunner(app, access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    server = site._server
    assert isinstance(server, asyncio.base_events.Server)
    bound = server.sockets[0].getsockname()
    return runner, f"http://{host}:{bound[1]}"
