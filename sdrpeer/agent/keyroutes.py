"""HTTP routes of the key commands (sdrpeer.agent.keyadmin): every one needs a token.

How it works: `GET /v1/keys` is this robot's ring (key ids only); `POST /v1/keys` applies one
change here (what an agent posts to its peers, with the peer token); `GET /v1/keys/fleet` and
`POST /v1/keys/fleet` are the operator's: every robot's ring, and one change applied on every
robot (`{"op": "add", "key": HEX}`, `{"op": "primary"|"retire", "key_id": ID}`). A change that
would lock a robot out is refused with 409 and changes nothing; bad input is 400 naming the
field. The agent exposes its `KeyAdmin` as `keys`.
"""

from __future__ import annotations

import binascii

from aiohttp import web

from sdrpeer.agent.keyadmin import OPS, KeyAdmin, KeyChangeRefused, ring_json
from sdrpeer.api.app import Route, json_error, json_object, require_token, view_of
from sdrpeer.errors import ConfigError
from sdrpeer.keys.keyring import MIN_KEY_SIZE, parse_key, parse_key_id

__all__ = ["ROUTES"]


def _admin(request: web.Request) -> KeyAdmin:
    admin = getattr(view_of(request), "keys", None)
    if not isinstance(admin, KeyAdmin):
        raise web.HTTPNotFound(reason="this agent has no key commands")
    return admin


@require_token
async def get_keys(request: web.Request) -> web.Response:
    """GET /v1/keys: this robot's ring (ids, the primary's first)."""
    admin = _admin(request)
    try:
        return web.json_response(ring_json(admin.name, admin.current()))
    except KeyChangeRefused as exc:
        return json_error(409, str(exc))


async def post_keys(request: web.Request) -> web.Response:
    """POST /v1/keys: one change, applied on this robot only (from another agent)."""
    admin = _admin(request)
    body = await json_object(request, '{"op": "primary", "key_id": "1a2b3c4d"}')
    try:
        return web.json_response(admin.change_here(body))
    except KeyChangeRefused as exc:
        return json_error(409, str(exc))
    except ConfigError as exc:
        return json_error(400, str(exc))


@require_token
async def get_fleet_keys(request: web.Request) -> web.Response:
    """GET /v1/keys/fleet: every alive robot's ring."""
    admin = _admin(request)
    try:
        return web.json_response(await admin.fleet_list())
    except KeyChangeRefused as exc:
        return json_error(409, str(exc))


async def post_fleet_keys(request: web.Request) -> web.Response:
    """POST /v1/keys/fleet: one change applied on every alive robot."""
    admin = _admin(request)
    body = await json_object(request, '{"op": "add", "key": "HEX"}')
    op = body.get("op")
    if op not in OPS:
        return json_error(400, f'field "op": expected one of {", ".join(OPS)}, got {op!r}')
    key: bytes | None = None
    kid: bytes | None = None
    try:
        if op == "add":
            key = parse_key(str(body.get("key", "")))
            if len(key) < MIN_KEY_SIZE:
                raise ValueError(f"{len(key)} bytes, at least {MIN_KEY_SIZE} needed")
        else:
            kid = parse_key_id(str(body.get("key_id", "")))
    except (ValueError, binascii.Error) as exc:
        field = "key" if op == "add" else "key_id"
        return json_error(400, f'field "{field}": {exc}')
    try:
        return web.json_response(await admin.fleet_change(op, key, kid))
    except KeyChangeRefused as exc:
        return json_error(409, str(exc))
    except ConfigError as exc:
        return json_error(409, str(exc))


ROUTES = [
    Route("GET", "/v1/keys", get_keys),
    Route("POST", "/v1/keys", post_keys),
    Route("GET", "/v1/keys/fleet", get_fleet_keys),
    Route("POST", "/v1/keys/fleet", post_fleet_keys),
]
