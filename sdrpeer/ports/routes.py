"""HTTP routes of the port tools (`sdrpeer port ...`): list, connect, disconnect, tap, inject, feed.

How it works: the agent does the work, the CLI only talks HTTP (it never holds a data key).
- `GET /v1/ports`: every port of every instance this agent hosts (sdrpeer.ports.catalog).
- `POST /v1/ports/connect {"from": "A.out", "to": "B.in", "policy": {...}, "id": ...}`: a
  run-time connection (rtcon), kept beside the plan's by the instance manager
  (sdrpeer.runtime.adhoc); refused for an unknown port, a port of the wrong direction, or two
  typed ports of different types. A receiver on another robot is checked by asking its agent's
  `GET /v1/ports`, and reached at the data address its record gives.
  `POST /v1/ports/disconnect {"id": ...}` (or from/to) undoes it.
- `POST /v1/ports/tap {"ports": [...], "count": N, "duration": S, "decode": bool, "policy":
  {...}}`: the agent starts a tap (sdrpeer.ports.tap), connects each OutPort to it (policy
  `push: new` unless given) and streams what arrives as chunked msgpack: a header map
  `{"ports": [{ref, direction, type, fields, robot}], "t0": ns}`, then one
  `[index, received_ns, seq, value]` per frame (`decode`: typed values as maps of their
  fields), then `{"end": reason, "frames": n, "dropped": k}`. The tap's connections go when the
  stream ends, whatever ends it (count, duration, the client leaving).
- `POST /v1/ports/inject {"port": "B.in", "value": ..., "rate": HZ, "count": N}`: the agent
  sends the value (a typed port's as a map of its fields, checked: sdrpeer.ports.values) `count`
  times at `rate` through a connection of its own (sdrpeer.ports.inject), until the client
  leaves.
- `POST /v1/ports/feed?port=B.in&port=...[&type=ID&type=...]` with a chunked msgpack body of
  `[index, value]`: each value goes as it is (already in its wire form) to the port at `index`,
  in order, as it arrives (replay paces itself). `type` (one per port, empty for untyped) says
  what the values are (a recording's schema): a typed port of another type is refused. A port
  named may be an OutPort: the values then go to every InPort its connections reach, as if it
  had sent them.
Every route but the list is a POST and so needs the token (a tap shows the robot's data, the
others change what flows). A request naming an instance of another robot is passed on to that
robot's agent with the peer token (sdrpeer.ports.forward), once; an agent that cannot (no peer
token: insecure, or its deployment stack not loaded) answers 404 naming the robot and its API.
"""

from __future__ import annotations

import asyncio
import os
import time
from dataclasses import replace
from typing import TYPE_CHECKING, Any, cast

import msgpack
from aiohttp import web

from sdrpeer.api.app import Route, instances_of, json_error, json_object, view_of
from sdrpeer.errors import ApiError, PortToolError, SpecError, shown
from sdrpeer.runtime.spec import ConnectionSpec, default_conn_id, validate_policy

if TYPE_CHECKING:  # loaded on a port tool's first use, not at the agent's start
    from sdrpeer.ports.catalog import Catalog, PortFacts
    from sdrpeer.ports.inject import Injector, Target
    from sdrpeer.runtime.manager import InstanceManager

TAP_POLICY = {"push": "new"}
"""A tap's default policy: only the newest value waits, so a slow reader never blocks a robot."""
MAX_TAP_S = 24 * 3600.0
MAX_COUNT = 10**9
MAX_RATE = 10_000.0
TAP_BUFFER = 4096
"""Frames a tap keeps for a reader that lags (the oldest go first; counted as dropped)."""
TAP_INSTANCE = "sdrpeer-tap"
"""The `to` of a tap's connections (its address is explicit: `to_addr`)."""
_POLL = 0.5
"""How often a waiting tap checks that its client is still there."""


async def _catalog(request: web.Request) -> Catalog:
    """The ports hosted here (their classes imported, off the event loop)."""
    from sdrpeer.ports.catalog import Catalog  # noqa: PLC0415 - see TYPE_CHECKING above

    view = view_of(request)
    manager = cast("InstanceManager", instances_of(request))

    def elsewhere(name: str) -> tuple[str, str | None] | None:
        for member in view.members_view():
            if member.get("name") == view.name:
                continue
            if any(i.get("name") == name for i in member.get("instances") or []):
                return str(member["name"]), member.get("api")
        return None

    catalog = Catalog(manager, view.name, elsewhere)
    await catalog.warm()
    return catalog


def _peer_token(request: web.Request) -> str | None:
    coordinator = getattr(view_of(request), "coordinator", None)
    token = getattr(coordinator, "token", None)
    return token if isinstance(token, str) and token else None


def _relay_to(request: web.Request, catalog: Catalog, refs: list[str]) -> tuple[str, str] | None:
    """(API, peer token) of the robot to pass the request on to, None to serve it here;
    PortToolError when it can be neither (unknown, spread, already passed on, no token)."""
    from sdrpeer.ports.forward import forwarded  # noqa: PLC0415 - see TYPE_CHECKING above

    owner = catalog.owner(refs)
    if owner is None:
        return None
    robot, api = owner
    token = _peer_token(request)
    if api is None or token is None or forwarded(request):
        where = f" (API {api})" if api else ""
        raise PortToolError(f"the ports are on {robot}, not {catalog.robot}: ask it{where}", 404)
    return api, token


def _fail(exc: PortToolError) -> web.Response:
    return json_error(exc.status, str(exc))


def _number(body: dict[str, Any], key: str, default: float | None, high: float) -> float | None:
    value = body.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int | float) or not 0 < value <= high:
        raise PortToolError(
            f"field {key!r}: expected a number in (0, {high:g}], got {shown(value)}"
        )
    return float(value)


def _policy(body: dict[str, Any], default: dict[str, Any]) -> tuple[tuple[str, Any], ...]:
    try:
        return validate_policy(body.get("policy", default), "policy")
    except SpecError as exc:
        raise PortToolError(str(exc)) from None


async def get_ports(request: web.Request) -> web.Response:
    """GET /v1/ports: every port of every instance hosted here."""
    return web.json_response((await _catalog(request)).listing())


async def post_connect(request: web.Request) -> web.Response:
    """POST /v1/ports/connect: a run-time connection from an OutPort to an InPort (on this
    robot, or on another: its agent is asked what the port is)."""
    body = await json_object(request, '{"from": "A.out", "to": "B.in"}')
    catalog = await _catalog(request)
    try:
        relay = _relay_to(request, catalog, [str(body.get("from", ""))])
        if relay is not None:
            return await _relay_json(request, relay, body)
        out = catalog.port(str(body.get("from", "")), "out", "from")
        to = str(body.get("to", ""))
        remote = catalog.owner([to])
        if remote is None:
            into = catalog.port(to, "in", "to")
            into_ref, into_instance, into_port, into_type = (
                into.ref,
                into.instance,
                into.port,
                into.type_id,
            )
        else:
            into_ref, into_instance, into_port = to, *catalog.split(to, "to")
            into_type = await _remote_in_port(request, remote, into_instance, into_port)
        if out.type_id is not None and into_type is not None and out.type_id != into_type:
            raise PortToolError(
                f"type mismatch: {out.ref} sends {out.type_id}, {into_ref} takes {into_type}",
                409,
            )
        cid = body.get("id") or default_conn_id(out.instance, out.port, into_instance, into_port)
        if not isinstance(cid, str) or len(cid) > 255:
            raise PortToolError(f"field 'id': expected a string, got {cid!r}")
        conn = ConnectionSpec(cid, out.port, into_instance, into_port, _policy(body, {}))
        try:
            catalog.manager.add_connection(out.instance, conn, remote=remote is not None)
        except ValueError as exc:
            raise PortToolError(str(exc), 409) from None
    except PortToolError as exc:
        return _fail(exc)
    return web.json_response({"id": cid, "from": out.ref, "to": into_ref})


async def _remote_in_port(
    request: web.Request, owner: tuple[str, str | None], instance: str, port: str
) -> str | None:
    """The type id of an InPort on another robot, as its agent lists it; PortToolError when it
    has no such in-port or cannot be asked."""
    from sdrpeer.api.peer_client import call  # noqa: PLC0415 - see TYPE_CHECKING above

    robot, api = owner
    token = _peer_token(request)
    if api is None or token is None:
        raise PortToolError(f"{instance} is on {robot}, whose ports cannot be asked", 404)
    try:
        status, rows = await call(api, "GET", "/v1/ports", token)
    except ApiError as exc:
        raise PortToolError(f"{robot} cannot be asked for its ports: {exc}", 502) from None
    if status != 200 or not isinstance(rows, list):
        raise PortToolError(f"{robot} answered {status} for its ports", 502)
    for row in rows:
        if row.get("instance") == instance and row.get("port") == port:
            if row.get("direction") != "in":
                raise PortToolError(f"to: {instance}.{port} is not an in-port", 409)
            type_id = row.get("type")
            return type_id if isinstance(type_id, str) else None
    known = ", ".join(str(r.get("port")) for r in rows if r.get("instance") == instance)
    raise PortToolError(f"to: {instance} on {robot} has no port {port!r} (ports: {known})", 404)


async def post_disconnect(request: web.Request) -> web.Response:
    """POST /v1/ports/disconnect {"id": ...} or {"from": "A.out", "to": "B.in"}."""
    body = await json_object(request, '{"id": "A.out->B.in"}')
    manager = cast("InstanceManager", instances_of(request))
    cid = body.get("id")
    if cid is None and "from" in body:
        try:
            relay = _relay_to(request, await _catalog(request), [str(body["from"])])
        except PortToolError as exc:
            return _fail(exc)
        if relay is not None:  # the sender's robot holds the connection
            return await _relay_json(request, relay, body)
    if cid is None and "from" in body and "to" in body:
        frm, to = str(body["from"]), str(body["to"])
        cid = next(
            (
                c.id
                for sender, c in manager.adhoc_connections()
                if f"{sender}.{c.out_port}" == frm and f"{c.to_instance}.{c.in_port}" == to
            ),
            None,
        )
    if not isinstance(cid, str) or not manager.remove_connection(cid):
        made = ", ".join(c.id for _, c in manager.adhoc_connections()) or "none"
        return json_error(404, f"no run-time connection {cid!r} here (run-time ones: {made})")
    return web.json_response({"removed": cid})


async def _relay_json(
    request: web.Request, relay: tuple[str, str], body: dict[str, Any]
) -> web.Response:
    from sdrpeer.ports.forward import relay_json  # noqa: PLC0415 - see TYPE_CHECKING above

    return await relay_json(request, relay[0], request.path, relay[1], body)


def _header(facts: list[PortFacts], robot: str) -> dict[str, Any]:
    from sdrpeer.ports.values import schema_fields  # noqa: PLC0415 - see TYPE_CHECKING above

    return {
        "ports": [
            {
                "ref": f.ref,
                "direction": f.direction,
                "type": f.type_id,
                "fields": schema_fields(f.message),
                "robot": robot,
            }
            for f in facts
        ],
        "t0": time.time_ns(),
    }


async def post_tap(request: web.Request) -> web.StreamResponse:
    """POST /v1/ports/tap: stream what OutPorts send (print, record)."""
    from sdrpeer.ports.tap import Tap  # noqa: PLC0415 - see TYPE_CHECKING above
    from sdrpeer.ports.values import to_fields  # noqa: PLC0415

    body = await json_object(request, '{"ports": ["Cam.image"], "count": 10}')
    catalog = await _catalog(request)
    refs = body.get("ports")
    try:
        if not isinstance(refs, list) or not refs:
            raise PortToolError("field 'ports': expected a list of \"Instance.port\"")
        relay = _relay_to(request, catalog, [str(r) for r in refs])
        if relay is not None:
            from sdrpeer.ports.forward import relay_stream  # noqa: PLC0415

            return await relay_stream(request, relay[0], request.path, relay[1], body)
        facts = [catalog.port(str(r), "out", f"ports[{i}]") for i, r in enumerate(refs)]
        count = _number(body, "count", None, MAX_COUNT)
        duration = _number(body, "duration", None, MAX_TAP_S)
        policy = _policy(body, TAP_POLICY)
    except PortToolError as exc:
        return _fail(exc)
    decode = bool(body.get("decode", False))
    manager = catalog.manager
    tap = Tap(len(facts), manager.data_keys, limit=TAP_BUFFER)
    await tap.start()
    session = os.urandom(4).hex()
    ids: list[str] = []
    response = web.StreamResponse(headers={"Content-Type": "application/x-msgpack"})
    response.enable_chunked_encoding()
    sent, reason = 0, "duration"
    try:
        for i, f in enumerate(facts):
            cid = f"tap-{session}-{i}"
            spec = ConnectionSpec(
                cid, f.port, TAP_INSTANCE, tap.in_port(i), policy, to_addr=tap.address
            )
            try:
                manager.add_connection(f.instance, spec)
            except KeyError:
                return json_error(404, f"{f.instance} is no longer hosted here")
            ids.append(cid)
        await response.prepare(request)
        await response.write(msgpack.packb(_header(facts, catalog.robot)))
        loop = asyncio.get_running_loop()
        deadline = None if duration is None else loop.time() + duration
        while True:
            if count is not None and sent >= count:
                reason = "count"
                break
            transport = request.transport
            if transport is None or transport.is_closing():
                reason = "client left"
                break
            wait = _POLL if deadline is None else min(_POLL, deadline - loop.time())
            if wait <= 0:
                break
            frame = await tap.next(wait)
            if frame is None:
                continue
            index, received, seq, value = frame
            message = facts[index].message
            if decode and message is not None:
                value = to_fields(message, value)
            await response.write(msgpack.packb([index, received, seq, value]))
            sent += 1
        end = {"end": reason, "frames": sent, "dropped": tap.dropped}
        await response.write(msgpack.packb(end))
        await response.write_eof()
    except (ConnectionResetError, ConnectionError):
        pass
    finally:
        for cid in ids:
            manager.remove_connection(cid)
        await tap.close()
    return response


async def post_inject(request: web.Request) -> web.Response:
    """POST /v1/ports/inject: send a value to an InPort `count` times at `rate`."""
    from sdrpeer.ports.inject import Injector  # noqa: PLC0415 - see TYPE_CHECKING above
    from sdrpeer.ports.values import to_wire  # noqa: PLC0415

    body = await json_object(request, '{"port": "B.in", "value": 1}')
    catalog = await _catalog(request)
    try:
        relay = _relay_to(request, catalog, [str(body.get("port", ""))])
        if relay is not None:
            return await _relay_json(request, relay, body)
        facts = catalog.port(str(body.get("port", "")), "in")
        if "value" not in body:
            raise PortToolError("field 'value': missing")
        value = body["value"]
        if facts.message is not None:
            value = to_wire(facts.message, value)
        count = int(_number(body, "count", 1, MAX_COUNT) or 1)
        rate = _number(body, "rate", None, MAX_RATE)
        injector = Injector(_targets(catalog, facts), catalog.manager.data_keys)
        await injector.start()
    except PortToolError as exc:
        return _fail(exc)
    loop = asyncio.get_running_loop()
    start = loop.time()
    try:
        for n in range(count):
            if rate is not None:
                delay = start + n / rate - loop.time()
                if delay > 0:
                    await asyncio.sleep(delay)  # the pace asked for
            transport = request.transport
            if transport is None or transport.is_closing():
                break  # the client left (Ctrl-C): stop sending
            for i in range(len(injector.targets)):
                await injector.send(i, value)
    except PortToolError as exc:
        return _fail(exc)
    finally:
        await injector.close()
    return web.json_response({"port": facts.ref, "sent": sum(injector.sent)})


def _targets(catalog: Catalog, facts: PortFacts) -> list[Target]:
    """Where values for `facts` go: the InPort itself, or every InPort an OutPort reaches."""
    from sdrpeer.ports.inject import Target  # noqa: PLC0415 - see TYPE_CHECKING above

    manager = catalog.manager
    if facts.direction == "in":
        addr = manager.data_address(facts.instance)
        if addr is None:
            raise PortToolError(f"{facts.instance} is not running (no data address yet)", 409)
        return [Target(facts.ref, addr, facts.port, facts.type_id)]
    targets = [
        Target(f"{conn.to_instance}.{conn.in_port}", addr, conn.in_port, facts.type_id)
        for conn, addr in manager.made_connections(facts.instance).values()
        if conn.out_port == facts.port and conn.to_instance != TAP_INSTANCE
    ]
    if not targets:
        raise PortToolError(f"{facts.ref} is connected to no InPort: nothing to feed", 409)
    return targets


async def post_feed(request: web.Request) -> web.Response:
    """POST /v1/ports/feed?port=...: values in their wire form, streamed, to ports (replay)."""
    from sdrpeer.ports.inject import Injector  # noqa: PLC0415 - see TYPE_CHECKING above

    catalog = await _catalog(request)
    refs = request.query.getall("port", [])
    types = request.query.getall("type", [])
    try:
        if not refs:
            raise PortToolError("query 'port': name at least one Instance.port")
        if types and len(types) != len(refs):
            raise PortToolError(f"query 'type': one per port ({len(refs)}), got {len(types)}")
        relay = _relay_to(request, catalog, refs)
        if relay is not None:
            from sdrpeer.ports.forward import relay_body  # noqa: PLC0415

            return await relay_body(request, relay[0], request.path_qs, relay[1])
        targets_of = []
        for i, ref in enumerate(refs):
            facts = catalog.port(ref, None, f"port[{i}]")
            given = (types[i] or None) if types else facts.type_id
            if given is not None and facts.type_id is not None and given != facts.type_id:
                raise PortToolError(
                    f"type mismatch: the values for {ref} are {given}, it takes {facts.type_id}",
                    409,
                )
            targets_of.append([replace(t, type_id=given) for t in _targets(catalog, facts)])
        flat = [t for ts in targets_of for t in ts]
        injector = Injector(flat, catalog.manager.data_keys)
        await injector.start()
    except PortToolError as exc:
        return _fail(exc)
    first = [sum(len(ts) for ts in targets_of[:i]) for i in range(len(targets_of))]  # conn index
    unpacker = msgpack.Unpacker(raw=False, max_buffer_size=64 * 1024 * 1024)
    frames = received = whole = 0  # whole: bytes up to the end of the last complete item
    try:
        async for chunk in request.content.iter_any():
            received += len(chunk)
            unpacker.feed(chunk)
            for item in unpacker:
                whole = unpacker.tell()
                if not isinstance(item, list) or len(item) != 2 or type(item[0]) is not int:
                    raise PortToolError(f"frame {frames + 1}: expected [index, value]")
                index, value = item
                if not 0 <= index < len(refs):
                    raise PortToolError(f"frame {frames + 1}: no port at index {index}")
                for k in range(len(targets_of[index])):
                    await injector.send(first[index] + k, value)
                frames += 1
        if whole != received:
            raise PortToolError(f"frame {frames + 1}: the body ends inside it")
    except PortToolError as exc:
        return _fail(exc)
    except (msgpack.UnpackException, ValueError) as exc:
        return json_error(400, f"frame {frames + 1}: not msgpack: {exc}")
    finally:  # whatever ended the body (the client gone mid-way too): no sender left behind
        await injector.close()
    sent = _per_ref(injector, first, targets_of)
    return web.json_response({"frames": frames, "sent": dict(zip(refs, sent, strict=True))})


def _per_ref(injector: Injector, first: list[int], targets_of: list[list[Target]]) -> list[int]:
    return [
        sum(injector.sent[first[i] + k] for k in range(len(ts))) for i, ts in enumerate(targets_of)
    ]


ROUTES: list[Route] = [
    Route("GET", "/v1/ports", get_ports),
    Route("POST", "/v1/ports/connect", post_connect),
    Route("POST", "/v1/ports/disconnect", post_disconnect),
    Route("POST", "/v1/ports/tap", post_tap),
    Route("POST", "/v1/ports/inject", post_inject),
    Route("POST", "/v1/ports/feed", post_feed),
]
