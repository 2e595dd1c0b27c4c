"""JSON requests from an agent to other agents' APIs (aiohttp client, short timeout).

How it works: one `ClientSession` per event loop is kept open (keep-alive connections to the
peers: a plan push costs one request, not a TCP and session set-up) and closed by `close()` when
the agent stops. Lives in `sdrpeer.api` so that aiohttp is imported without a CA store (see the
package).
"""

from __future__ import annotations

import asyncio
from typing import Any

import aiohttp

from sdrpeer.errors import ApiError

TIMEOUT = 3.0
_sessions: dict[asyncio.AbstractEventLoop, aiohttp.ClientSession] = {}


def _session() -> aiohttp.ClientSession:
    loop = asyncio.get_running_loop()
    session = _sessions.get(loop)
    if session is None or session.closed:
        session = aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=TIMEOUT))
        _sessions[loop] = session
    return session


async def close() -> None:
    """Close this loop's session (the agent calls it when it stops)."""
    session = _sessions.pop(asyncio.get_running_loop(), None)
    if session is not None:
        await session.close()


async def call(
    api: str, method: str, path: str, token: str, *, body: Any = None
) -> tuple[int, Any]:
    """(status, decoded JSON body) of one request; ApiError if the agent cannot be reached."""
    return await _request(api, method, path, token, json=body)


async def post_packed(api: str, path: str, token: str, data: bytes) -> tuple[int, Any]:
    """POST a msgpack body; (status, decoded JSON answer); ApiError if it cannot be delivered."""
    return await _request(api, "POST", path, token, data=data, content_type="application/msgpack")


async def _request(
    api: str, method: str, path: str, token: str, *, content_type: str | None = None, **body: Any
) -> tuple[int, Any]:
    headers = {"Authorization": f"Bearer {token}"}
    if content_type is not None:
        headers["Content-Type"] = content_type
    try:
        async with _session().request(method, api + path, headers=headers, **body) as resp:
            doc = await resp.json(content_type=None)
            return resp.status, doc
    except (aiohttp.ClientError, TimeoutError, ValueError) as e:
        raise ApiError(f"{api}{path}: {type(e).__name__}: {e}") from None
