"""One JSON request from an agent to another agent's API (aiohttp client, short timeout).

Lives in `sdrpeer.api` so that aiohttp is imported without a CA store (see the package).
"""

from __future__ import annotations

from typing import Any

import aiohttp

from sdrpeer.errors import ApiError

TIMEOUT = 3.0


async def call(
    api: str, method: str, path: str, token: str, *, body: Any = None
) -> tuple[int, Any]:
    """(status, decoded JSON body) of one request; ApiError if the agent cannot be reached."""
    headers = {"Authorization": f"Bearer {token}"}
    try:
        async with (
            aiohttp.ClientSession(timeout=aiohttp.ClientTimeout(total=TIMEOUT)) as session,
            session.request(method, api + path, json=body, headers=headers) as resp,
        ):
            doc = await resp.json(content_type=None)
            return resp.status, doc
    except (aiohttp.ClientError, TimeoutError, ValueError) as e:
        raise ApiError(f"{api}{path}: {type(e).__name__}: {e}") from None
