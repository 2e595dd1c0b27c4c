"""Port tool requests for an instance on another robot, passed on to that robot's agent.

How it works: the agent that hosts an instance is the one that taps it, injects into it or
connects it (it holds the instance's data address and its connections). A request that names an
instance of another robot is sent on, once, to that robot's API with this agent's peer token
(derived from the cluster key: every agent accepts it) and a `X-Sdrpeer-Forwarded` header, so a
request is never passed on twice; the answer comes back as it is. A tap's stream and a feed's
body are relayed chunk by chunk as they come (`relay_stream`, `relay_body`); the relay of a tap
or of an inject checks every `poll` seconds that its own client is still there, and ends the
upstream request when it is not (the other agent then removes its tap, or stops injecting).
"""

from __future__ import annotations

import asyncio
import contextlib
from collections.abc import AsyncIterator
from typing import Any

import aiohttp
from aiohttp import web

HEADER = "X-Sdrpeer-Forwarded"
CONNECT_WITHIN = 5.0
"""Seconds to reach the other agent."""


def _headers(token: str, content_type: str) -> dict[str, str]:
    return {"Authorization": f"Bearer {token}", HEADER: "1", "Content-Type": content_type}


def _session() -> aiohttp.ClientSession:
    timeout = aiohttp.ClientTimeout(total=None, sock_connect=CONNECT_WITHIN)
    return aiohttp.ClientSession(timeout=timeout)


def forwarded(request: web.Request) -> bool:
    """Whether `request` was passed on by another agent already."""
    return request.headers.get(HEADER) == "1"


async def _passed_back(resp: aiohttp.ClientResponse) -> web.Response:
    body = await resp.read()
    return web.Response(body=body, status=resp.status, content_type="application/json")


async def relay_json(
    request: web.Request, api: str, path: str, token: str, body: Any, *, poll: float = 0.5
) -> web.Response:
    """POST a JSON body to the other agent; its answer. While it is awaited (an inject may run
    for long), our client is checked every `poll` seconds: once it has left, the upstream
    request is ended, so the other agent stops too (it checks its own client the same way)."""

    async def ask() -> web.Response:
        async with (
            _session() as session,
            session.post(
                api + path, json=body, headers=_headers(token, "application/json")
            ) as resp,
        ):
            return await _passed_back(resp)

    upstream = asyncio.ensure_future(ask())
    try:
        while not upstream.done():
            await asyncio.wait((upstream,), timeout=poll)
            transport = request.transport
            if not upstream.done() and (transport is None or transport.is_closing()):
                upstream.cancel()  # our client left: end the request upstream
                with contextlib.suppress(asyncio.CancelledError):
                    await upstream
                return web.Response(status=499)
        return upstream.result()
    except (aiohttp.ClientError, TimeoutError) as e:
        return web.json_response({"error": f"cannot reach {api}: {e}"}, status=502)
    finally:
        if not upstream.done():  # we were cancelled ourselves
            upstream.cancel()


async def relay_stream(
    request: web.Request, api: str, path: str, token: str, body: Any, *, poll: float = 0.5
) -> web.StreamResponse:
    """POST a JSON body to the other agent and stream its answer back to our client."""
    try:
        async with (
            _session() as session,
            session.post(
                api + path, json=body, headers=_headers(token, "application/json")
            ) as resp,
        ):
            if resp.status != 200:
                return await _passed_back(resp)
            out = web.StreamResponse(headers={"Content-Type": resp.content_type})
            out.enable_chunked_encoding()
            await out.prepare(request)
            while True:
                transport = request.transport
                if transport is None or transport.is_closing():
                    break  # our client left: leaving the block ends the upstream request
                chunk = b""
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(poll):
                        chunk = await resp.content.readany()
                if chunk:
                    await out.write(chunk)
                elif resp.content.at_eof():
                    await out.write_eof()
                    break
            return out
    except (aiohttp.ClientError, TimeoutError) as e:
        return web.json_response({"error": f"cannot reach {api}: {e}"}, status=502)
    except ConnectionError:
        return web.Response(status=499)  # our client left while we wrote


async def relay_body(request: web.Request, api: str, path_qs: str, token: str) -> web.Response:
    """POST our client's body to the other agent as it arrives; its answer."""

    async def chunks() -> AsyncIterator[bytes]:
        async for chunk in request.content.iter_any():
            yield chunk

    try:
        async with (
            _session() as session,
            session.post(
                api + path_qs, data=chunks(), headers=_headers(token, "application/x-msgpack")
            ) as resp,
        ):
            return await _passed_back(resp)
    except (aiohttp.ClientError, TimeoutError) as e:
        return web.json_response({"error": f"cannot reach {api}: {e}"}, status=502)
