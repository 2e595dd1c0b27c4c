"""HTTP routes of the dashboard: the page, its vendored scripts, the history and the live stream.

How it works: `GET /` is the page (`static/index.html`); `GET /dashboard/{file}` serves only the
files shipped in `sdrpeer/dashboard/static` (robots are offline: no CDN); `GET /v1/history` is
the metric history as columns (`?since=` unix seconds); `GET /v1/stream` is the server-sent
event stream (`stream.Hub`; `?once=1`: what a new page gets, then the end: the page's snapshot
mode, `/?snapshot=1`, reads it so a headless browser's screenshot finishes). All are read-only,
so no token: the API listens on loopback unless told otherwise. The agent exposes its `Feed` as
`dashboard`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Final

from aiohttp import web

from sdrpeer.api.app import Route, view_of
from sdrpeer.dashboard.feed import Feed

STATIC: Final = Path(__file__).resolve().parent / "static"
_TYPES: Final = {
    ".html": "text/html",
    ".js": "text/javascript",
    ".css": "text/css",
    ".txt": "text/plain",
}


def _feed(request: web.Request) -> Feed:
    feed = getattr(view_of(request), "dashboard", None)
    if not isinstance(feed, Feed):
        raise web.HTTPNotFound(reason="this agent has no dashboard")
    return feed


def _file(name: str) -> web.Response:
    path = STATIC / name
    kind = _TYPES.get(path.suffix)
    if kind is None or path.parent != STATIC or not path.is_file():
        raise web.HTTPNotFound(reason=f"no dashboard file {name!r}")
    return web.Response(
        body=path.read_bytes(),
        content_type=kind,
        charset="utf-8",
        headers={"Cache-Control": "no-cache"},
    )


async def get_index(request: web.Request) -> web.Response:
    """GET /: the dashboard page."""
    _feed(request)
    return _file("index.html")


async def get_static(request: web.Request) -> web.Response:
    """GET /dashboard/{name}: one of the page's vendored files."""
    return _file(request.match_info["name"])


async def get_history(request: web.Request) -> web.Response:
    """GET /v1/history?since=T: every robot's metric series kept by this agent."""
    try:
        since = float(request.query.get("since", "-inf"))
    except ValueError:
        raise web.HTTPBadRequest(reason="since: expected unix seconds") from None
    return web.json_response(_feed(request).history.series(since))


async def get_stream(request: web.Request) -> web.StreamResponse:
    """GET /v1/stream: hello, history, events, then samples and events as they happen (SSE);
    `?once=1`: hello, history, events, one sample, `end`, and the response ends."""
    feed = _feed(request)
    once = request.query.get("once", "") not in ("", "0", "false")
    return await feed.hub.serve(request, feed.hello, once=once)


ROUTES = [
    Route("GET", "/", get_index),
    Route("GET", "/dashboard/{name}", get_static),
    Route("GET", "/v1/history", get_history),
    Route("GET", "/v1/stream", get_stream),
]
