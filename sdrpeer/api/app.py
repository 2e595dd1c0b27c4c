"""The agent's HTTP API (aiohttp): JSON under /v1, Prometheus text at /metrics.

How it works:
- `ROUTES` is the route table; a later feature adds a `Route` (or calls `add_routes`).
- Reads are open (the API listens on loopback by default). Every state-changing request (any
  method but GET/HEAD/OPTIONS), and any handler marked `@require_token`, needs
  `Authorization: Bearer <token>`; `auth_middleware` checks it with `hmac.compare_digest`.
- Every error is JSON `{"error": "..."}`, including 404/405 and unexpected exceptions.
"""

from __future__ import annotations

import asyncio
import hmac
import json
import logging
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from aiohttp import web

from sdrpeer.api.view import AgentView, InstancesView
from sdrpeer.errors import CommandError, ConfigError, LaunchRefused, clip
from sdrpeer.eventlog import naming
from sdrpeer.runtime import logfile
from sdrpeer.runtime.spec import INSTANCE_ACTIONS, InstanceSpec

log = logging.getLogger(__name__)

Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]
VIEW_KEY = web.AppKey("view", AgentView)
TOKEN_KEY = web.AppKey("token", str)
PEER_TOKEN_KEY = web.AppKey("peer_tokens", list[str])
"""Tokens other agents may present (one per cluster key); a list changed in place on rotation."""
REGISTRY_KEY = web.AppKey("registry", list[Any])
"""Holds the Prometheus registry once the first scrape made it (prometheus_client is loaded
then, not at start)."""
SAFE_METHODS = frozenset({"GET", "HEAD", "OPTIONS"})
MAX_EVENTS_LIMIT = 10_000
MAX_ABOUT = 64
"""Names one `GET /v1/events?about=` may ask for."""
MAX_NAME = 200
_TOKEN_ATTR = "_sdrpeer_requires_token"


@dataclass(frozen=True, slots=True)
class Route:
    """One entry of the route table."""

    method: str
    path: str
    handler: Handler


def require_token(handler: Handler) -> Handler:
    """Mark a handler as needing the bearer token even for GET (writes always need it)."""
    setattr(handler, _TOKEN_ATTR, True)
    return handler


def json_error(status: int, message: str) -> web.Response:
    """A JSON error response `{"error": message}`, long echoed input cut (`errors.clip`)."""
    return web.json_response({"error": clip(message)}, status=status)


async def json_object(request: web.Request, example: str = "{...}") -> dict[str, Any]:
    """The request body as a JSON object; 400 in the project's words when it is not UTF-8, not
    JSON or not an object (never a 500: `request.json()` let a non-UTF-8 body through)."""
    raw = await request.read()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise _bad(f"body is not UTF-8 text (byte {exc.start})") from None
    try:
        body = json.loads(text)
    except json.JSONDecodeError as exc:
        raise _bad(f"body is not JSON: {exc.msg} at line {exc.lineno} column {exc.colno}") from None
    except RecursionError:
        raise _bad("body is not JSON: nested too deeply") from None
    if not isinstance(body, dict):
        raise _bad(f"body must be a JSON object, e.g. {example}")
    return body


def _bad(message: str) -> web.HTTPBadRequest:
    return web.HTTPBadRequest(reason=message)  # error_middleware answers {"error": reason}


def view_of(request: web.Request) -> AgentView:
    """The AgentView the app was built with."""
    return request.app[VIEW_KEY]


def _needs_token(request: web.Request) -> bool:
    if request.method not in SAFE_METHODS:
        return True
    handler = request.match_info.handler
    return bool(getattr(handler, _TOKEN_ATTR, False))


def _token_ok(request: web.Request) -> bool:
    header = request.headers.get("Authorization", "")
    scheme, _, given = header.partition(" ")
    if scheme.lower() != "bearer" or not given:
        return False
    given_b = given.strip().encode()
    if hmac.compare_digest(given_b, request.app[TOKEN_KEY].encode()):
        return True
    peers = request.app.get(PEER_TOKEN_KEY) or []
    return any(hmac.compare_digest(given_b, peer.encode()) for peer in peers)


@web.middleware
async def auth_middleware(request: web.Request, handler: Handler) -> web.StreamResponse:
    """Reject unauthenticated state-changing requests with 401."""
    if _needs_token(request) and not _token_ok(request):
        response = json_error(401, "missing or wrong token: send Authorization: Bearer <token>")
        response.headers["WWW-Authenticate"] = 'Bearer realm="sdrpeer"'
        return response
    return await handler(request)


@web.middleware
async def error_middleware(request: web.Request, handler: Handler) -> web.StreamResponse:
    """Turn aiohttp's HTTP errors and unexpected exceptions into JSON errors."""
    try:
        return await handler(request)
    except web.HTTPException as exc:
        if exc.status < 400:
            raise
        return json_error(exc.status, exc.reason)
    except Exception:
        log.exception("API handler failed: %s %s", request.method, request.path)
        return json_error(500, "internal error (see the agent log)")


def _int_param(request: web.Request, name: str, default: int, low: int, high: int) -> int:
    text = request.query.get(name)
    if text is None:
        return default
    try:
        value = int(text)
    except ValueError:
        raise web.HTTPBadRequest(reason=f"{name} must be an integer, got {text!r}") from None
    if not low <= value <= high:
        raise web.HTTPBadRequest(reason=f"{name} must be in {low}..{high}, got {value}")
    return value


async def get_members(request: web.Request) -> web.Response:
    """GET /v1/members: every known member, sorted by name."""
    return web.json_response(view_of(request).members_view())


async def get_agent(request: web.Request) -> web.Response:
    """GET /v1/agent: this agent's counters and settings."""
    return web.json_response(view_of(request).agent_view())


async def get_events(request: web.Request) -> web.Response:
    """GET /v1/events?since=N&limit=M[&about=NAME...]: event log entries with id > since;
    with `about`, only those naming one of the names (`eventlog.naming`), the newest `limit`."""
    since = _int_param(request, "since", 0, 0, 2**63 - 1)
    limit = _int_param(request, "limit", 500, 1, MAX_EVENTS_LIMIT)
    about = request.query.getall("about", [])
    if not about:
        return web.json_response(view_of(request).events_view(since=since, limit=limit))
    if len(about) > MAX_ABOUT or any(len(a) > MAX_NAME for a in about):
        raise _bad(f"about: at most {MAX_ABOUT} names of at most {MAX_NAME} characters")
    entries = view_of(request).events_view(since=since, limit=MAX_EVENTS_LIMIT)
    names_it = naming(about)
    return web.json_response([e for e in entries if names_it(e)][-limit:])


async def get_metrics(request: web.Request) -> web.Response:
    """GET /metrics: Prometheus text exposition."""
    from sdrpeer.api import metrics  # noqa: PLC0415 - loaded on the first scrape, not at start

    made = request.app[REGISTRY_KEY]
    if not made:
        made.append(metrics.make_registry(view_of(request)))
    body = metrics.render(made[0])
    return web.Response(body=body, headers={"Content-Type": metrics.CONTENT_TYPE})


async def get_healthz(request: web.Request) -> web.Response:
    """GET /healthz: 200 while the agent serves requests; `ready` once everything it runs is
    up (an agent answers before its deployment stack has loaded)."""
    view = view_of(request)
    ready = bool(getattr(view, "ready", True))
    return web.json_response({"status": "ok", "name": view.name, "ready": ready})


async def post_robot(request: web.Request) -> web.Response:
    """POST /v1/robot: change this virtual robot's facts (JSON object of changes)."""
    changes = await json_object(request, '{"battery": "30%"}')
    if not changes:
        return json_error(400, 'body must be a non-empty JSON object, e.g. {"battery": "30%"}')
    view = view_of(request)
    try:
        new_metrics = view.set_virtual(changes)
    except ConfigError as exc:
        return json_error(400, str(exc))
    return web.json_response({"name": view.name, "metrics": new_metrics})


# --- component instances (sdrpeer.runtime) ----------------------------------------------------
LOG_FOLLOW_POLL = 0.2
LOG_FOLLOW_MAX_S = 3600
MAX_FOLLOWS = 16
"""Logs followed at once (`?follow=1`, 503 beyond): each holds a connection the API never sheds
(a request in progress), and reading is open to whoever can reach the API, so uncapped they
could hold every connection it keeps (docs/security.md, "The API under a connection flood")."""
FOLLOWS_KEY = web.AppKey("follows", list[int])
"""One count: the logs being followed now."""


def instances_of(request: web.Request) -> InstancesView:
    """The agent's instance manager; 404 on an agent that hosts no instances, 503 while it is
    starting."""
    view = view_of(request)
    manager = getattr(view, "instances", None)
    if manager is None and not getattr(view, "ready", True):
        raise web.HTTPServiceUnavailable(reason="the agent is starting: try again in a moment")
    if not isinstance(manager, InstancesView):
        raise web.HTTPNotFound(reason="this agent does not host component instances")
    return manager


def _known(request: web.Request) -> tuple[InstancesView, str]:
    manager, name = instances_of(request), request.match_info["name"]
    if manager.log_file(name) is None:
        raise web.HTTPNotFound(reason=f"no instance {name!r} on {view_of(request).name}")
    return manager, name


async def get_instances(request: web.Request) -> web.Response:
    """GET /v1/instances: every desired or running instance with its status."""
    return web.json_response(instances_of(request).status())


async def post_instances(request: web.Request) -> web.Response:
    """POST /v1/instances {"instances": [...], "replace": bool}: merge or set the desired set."""
    manager = instances_of(request)
    body = await json_object(request, '{"instances": [...], "replace": false}')
    if not isinstance(body.get("instances"), list):
        return json_error(400, 'body must be {"instances": [...], "replace": false}')
    replace_all = body.get("replace", False)
    if not isinstance(replace_all, bool):
        return json_error(400, "field 'replace': expected true or false")
    try:
        specs = [
            InstanceSpec.from_json(d, f"instances[{i}]") for i, d in enumerate(body["instances"])
        ]
    except ConfigError as exc:
        return json_error(400, str(exc))
    names = [s.name for s in specs]
    for i, name in enumerate(names):
        if name in names[:i]:
            return json_error(400, f"field 'instances[{i}].name': {name!r} given twice")
    try:
        desired = manager.set_desired(specs, replace_all=replace_all)
    except LaunchRefused as exc:
        return json_error(403, str(exc))
    return web.json_response({"desired": desired})


async def delete_instance(request: web.Request) -> web.Response:
    """DELETE /v1/instances/{name}: stop the instance and forget it."""
    manager, name = instances_of(request), request.match_info["name"]
    if not manager.remove(name):
        return json_error(404, f"no instance {name!r} in the desired set")
    return web.json_response({"removed": name})


async def post_instance_action(request: web.Request) -> web.Response:
    """POST /v1/instances/{name}/{action}: activate, deactivate, reset or restart."""
    manager, name = instances_of(request), request.match_info["name"]
    action = request.match_info["action"]
    if action not in INSTANCE_ACTIONS:
        return json_error(400, f"unknown action {action!r} (known: {', '.join(INSTANCE_ACTIONS)})")
    try:
        return web.json_response(await manager.act(name, action))
    except KeyError:
        return json_error(404, f"no instance {name!r} in the desired set")
    except CommandError as exc:
        return json_error(409, f"{name}: {exc}")


async def get_instance_logs(request: web.Request) -> web.StreamResponse:
    """GET /v1/instances/{name}/logs?tail=N[&follow=1]: the log as text; follow streams it."""
    manager, name = _known(request)
    path = manager.log_file(name)
    assert path is not None
    lines = _int_param(request, "tail", 100, 0, logfile.MAX_TAIL_LINES)
    if request.query.get("follow", "0") in ("0", "false", ""):
        return web.Response(body=logfile.tail(path, lines), content_type="text/plain")
    max_s = _int_param(request, "max_s", LOG_FOLLOW_MAX_S, 1, LOG_FOLLOW_MAX_S)
    follows = request.app[FOLLOWS_KEY]
    if follows[0] >= MAX_FOLLOWS:
        raise web.HTTPServiceUnavailable(reason=f"at most {MAX_FOLLOWS} logs followed at once")
    follows[0] += 1
    try:
        return await _follow(request, path, lines, max_s)
    finally:
        follows[0] -= 1


async def _follow(request: web.Request, path: Path, lines: int, max_s: int) -> web.StreamResponse:
    response = web.StreamResponse(headers={"Content-Type": "text/plain; charset=utf-8"})
    response.enable_chunked_encoding()
    await response.prepare(request)
    follower = logfile.Follower(path)
    await response.write(logfile.tail(path, lines))
    loop = asyncio.get_running_loop()
    deadline = loop.time() + max_s
    try:
        while loop.time() < deadline:
            transport = request.transport
            if transport is None or transport.is_closing():
                break
            data = follower.read_new()
            if data:
                await response.write(data)
            else:
                await asyncio.sleep(LOG_FOLLOW_POLL)
        await response.write_eof()
    except (ConnectionResetError, ConnectionError):
        pass
    return response


ROUTES: list[Route] = [
    Route("GET", "/healthz", get_healthz),
    Route("GET", "/metrics", get_metrics),
    Route("GET", "/v1/members", get_members),
    Route("GET", "/v1/agent", get_agent),
    Route("GET", "/v1/events", get_events),
    Route("POST", "/v1/robot", post_robot),
    Route("GET", "/v1/instances", get_instances),
    Route("POST", "/v1/instances", post_instances),
    Route("DELETE", "/v1/instances/{name}", delete_instance),
    Route("POST", "/v1/instances/{name}/{action}", post_instance_action),
    Route("GET", "/v1/instances/{name}/logs", get_instance_logs),
]


def add_routes(app: web.Application, routes: Iterable[Route]) -> None:
    """Register routes on an app built by `build_app` (token rules apply automatically)."""
    for route in routes:
        app.router.add_route(route.method, route.path, route.handler)


def build_app(
    view: AgentView,
    *,
    token: str,
    extra_routes: Iterable[Route] = (),
    peer_tokens: list[str] | None = None,
) -> web.Application:
    """The API application for one agent; `token` guards every state-changing route.

    `peer_tokens` (derived from the cluster keys) are accepted too: other agents use them. The
    list is kept as given, so the agent can change its contents when keys rotate.
    """
    if not token:
        raise ValueError("the API token must not be empty")
    app = web.Application(middlewares=[error_middleware, auth_middleware])
    app[VIEW_KEY] = view
    app[TOKEN_KEY] = token
    if peer_tokens is not None:
        app[PEER_TOKEN_KEY] = peer_tokens
    app[REGISTRY_KEY] = []
    app[FOLLOWS_KEY] = [0]
    add_routes(app, [*ROUTES, *extra_routes])
    return app
