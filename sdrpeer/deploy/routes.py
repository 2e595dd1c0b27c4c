"""HTTP routes of deployment: deploy, undeploy, status, and the plan exchanged between agents.

How it works: `POST /v1/deploy` takes a system (the JSON of a `SystemDef`, validated by the
CLI's loader; re-checked here by rebuilding it) and gives it to the allocator: this agent if it
holds the role, else it forwards the request to the allocator's API with the peer token. The
answer is the plan (200), an infeasible report (409: which constraint ruled out each robot), or
503 when no allocator is known yet or when the allocator hears robots whose records have not
arrived (an agent that just joined: the answer may change in a moment, so the CLI retries).
`GET/POST /v1/plan` are how agents fetch and push plans; `POST /v1/move` asks the allocator for a
planned move of one component (sdrpeer.deploy.move). `GET /v1/describe/{name}` answers
`sdrpeer describe` from the plan this robot holds (its explanation travels with it), the status,
the members and the events naming the subject in this agent's log and in those of the robots
concerned (its robots and the allocator, asked at once with `about=`; one that does not answer
within `DESCRIBE_ASK_S` is listed as unreachable).
"""

from __future__ import annotations

import asyncio
import time
from typing import TYPE_CHECKING, Any
from urllib.parse import quote

from aiohttp import web

from sdrpeer.alloc.result import Infeasible
from sdrpeer.api.app import Route, json_error, json_object, require_token, view_of
from sdrpeer.api.peer_client import call
from sdrpeer.config import NAME_RE
from sdrpeer.deploy.describe import (
    concerned_robots,
    describe_component,
    describe_robot,
    subject_kind,
    subject_names,
)
from sdrpeer.deploy.handoff_rules import APPLY, HOLD, StateMsg
from sdrpeer.errors import ApiError, MoveError, NotAllocator
from sdrpeer.plan import plan_from_json
from sdrpeer.runtime.handoff import MAX_STATE
from sdrpeer.system.classes import disagreements
from sdrpeer.system.model import SystemDef, system_from_json
from sdrpeer.system.recovery_defaults import ACTIONS

if TYPE_CHECKING:  # the deployment stack loads after the API is up (sdrpeer.agent.agent)
    from sdrpeer.deploy.coordinator import Coordinator


def _coord(request: web.Request) -> Coordinator:
    view = view_of(request)
    coord: Coordinator | None = getattr(view, "coordinator", None)
    if coord is None and not getattr(view, "ready", True):
        raise web.HTTPServiceUnavailable(reason="the agent is starting: try again in a moment")
    if coord is None:
        raise web.HTTPNotFound(reason="this agent does not deploy systems")
    return coord


DESCRIBE_ASK_S = 2.0
"""How long `GET /v1/describe` waits for another robot's events."""


async def get_describe(request: web.Request) -> web.Response:
    """GET /v1/describe/{name}: a component (or instance) or a robot: where, why, events,
    warnings (`sdrpeer.deploy.describe`)."""
    coord = _coord(request)
    view = view_of(request)
    name = request.match_info["name"]
    plan = coord.store.plan
    members = view.members_view()
    kind = subject_kind(name, plan, members)
    if kind is None:
        comps = [] if plan is None or plan.system is None else plan.system.components
        known = ", ".join([c.name for c in comps] + [str(m.get("name")) for m in members])
        return json_error(404, f"no component, instance or robot called {name!r} (known: {known})")
    names = subject_names(name, kind, plan)
    local = view.events_view(since=0, limit=10_000)
    asked = sorted(concerned_robots(name, kind, plan) - {coord.name})
    answers = await asyncio.gather(*(_events_of(coord, robot, names) for robot in asked))
    events = list(local)
    unreachable = []
    for robot, got in zip(asked, answers, strict=True):
        if got is None:
            unreachable.append(robot)
        else:
            events += got
    status = coord.status(time.time())
    if kind == "component":
        assert plan is not None
        doc = describe_component(name, plan, status, members, events)
    else:
        doc = describe_robot(name, plan, status, members, events)
    doc["asked"] = {"robots": [coord.name, *asked], "unreachable": unreachable}
    return web.json_response(doc)


async def _events_of(coord: Coordinator, robot: str, names: list[str]) -> list[Any] | None:
    """The events naming `names` in `robot`'s log, None when it cannot tell us in time."""
    rec = coord.cluster().alive.get(robot)
    if rec is None or rec.api is None:
        return None
    query = "&".join(f"about={quote(n)}" for n in names)
    try:
        async with asyncio.timeout(DESCRIBE_ASK_S):
            status, doc = await call(rec.api, "GET", f"/v1/events?limit=200&{query}", coord.token)
    except (ApiError, TimeoutError):
        return None
    return doc if status == 200 and isinstance(doc, list) else None


RECOVERY_STEPS = tuple(a for a in ACTIONS if a != "restart")
"""The recovery steps that change the plan (`restart` is done where the fault is)."""


async def _body(request: web.Request) -> dict[str, Any]:
    return await json_object(request)


async def _allocate(
    request: web.Request, system: SystemDef | None, body: dict[str, Any]
) -> web.Response:
    coord = _coord(request)
    origin = str(body.get("origin") or coord.name)
    try:
        result = await coord.deploy(system, origin)
    except NotAllocator as e:
        return await _forward(request, e.leader, {**body, "origin": origin})
    if isinstance(result, Infeasible):
        state = coord.cluster()
        waiting = sorted(state.heard - state.alive.keys())
        if waiting:
            return json_error(
                503,
                f"the system cannot be placed yet: {', '.join(waiting)} alive but not heard "
                f"from in full (no robot record yet); retry in a moment\n{result}",
            )
        return web.json_response(
            {"error": f"the system cannot be placed:\n{result}", "report": str(result)}, status=409
        )
    return web.json_response({"plan": result.to_json(), "allocator": coord.name})


async def _forward(request: web.Request, leader: str | None, body: dict[str, Any]) -> web.Response:
    view = view_of(request)
    if body.get("forwarded"):
        return json_error(503, f"{leader or 'no robot'} is not the allocator either; retry")
    api = getattr(view, "allocator_api", lambda: None)()
    if leader is None or api is None:
        return json_error(503, "no allocator elected yet; retry in a moment")
    try:
        status, doc = await call(
            api,
            request.method,
            request.path,
            _coord(request).token,
            body={**body, "forwarded": True},
        )
    except ApiError as e:
        return json_error(502, f"the allocator {leader} cannot be reached: {e}")
    return web.json_response(doc, status=status)


async def post_deploy(request: web.Request) -> web.Response:
    """POST /v1/deploy {"system": {...}, "origin": robot?}: allocate and publish a plan."""
    body = await _body(request)
    if not isinstance(body.get("system"), dict):
        return json_error(400, "field 'system': missing, or not an object (a loaded system file)")
    try:
        system = system_from_json(body["system"])
    except KeyError as e:
        return json_error(400, f"field 'system': not a system document: no field {e.args[0]!r}")
    except (TypeError, ValueError, AttributeError, IndexError):
        return json_error(
            400, "field 'system': not a system document: a field has the wrong type or value"
        )
    if not body.get("forwarded"):  # the first agent asked judges it (imports: in a thread)
        wrong = await asyncio.to_thread(disagreements, system)
        if wrong:
            return json_error(409, "connections the classes refuse: " + "; ".join(wrong))
    return await _allocate(request, system, body)


async def post_undeploy(request: web.Request) -> web.Response:
    """POST /v1/undeploy: a plan with no system (every robot stops what the plan ran)."""
    return await _allocate(request, None, await _body(request))


async def get_status(request: web.Request) -> web.Response:
    """GET /v1/status: each component with its robot, state, standbys and since when."""
    return web.json_response(_coord(request).status(time.time()))


@require_token
async def get_plan(request: web.Request) -> web.Response:
    """GET /v1/plan (token): the plan this robot holds."""
    plan = _coord(request).store.plan
    return web.json_response({"plan": None if plan is None else plan.to_json()})


async def post_plan(request: web.Request) -> web.Response:
    """POST /v1/plan {"plan": {...}} (token): an allocator pushes its plan; fenced by epoch."""
    body = await _body(request)
    try:
        plan = plan_from_json(body.get("plan"))
    except ValueError as e:
        return json_error(400, str(e))
    accepted = _coord(request).accept(plan, source=plan.allocator or "push")
    return web.json_response({"accepted": accepted})


async def post_recovery(request: web.Request) -> web.Response:
    """POST /v1/recovery {robot, component, instance, action} (token): a robot's recovery step
    that changes who is active; the allocator issues the new plan (others forward it there)."""
    body = await _body(request)
    coord = _coord(request)
    fields = []
    for key in ("robot", "component", "instance", "action"):
        value = body.get(key)
        if not isinstance(value, str) or not NAME_RE.fullmatch(value):
            return json_error(400, f"field {key!r}: expected a name, got {value!r:.80}")
        fields.append(value)
    if fields[3] not in RECOVERY_STEPS:
        steps = ", ".join(RECOVERY_STEPS)
        return json_error(400, f"field 'action': expected one of {steps}, got {fields[3]!r:.80}")
    try:
        result = await coord.recover_component(*fields)
    except NotAllocator as e:
        return await _forward(request, e.leader, body)
    except LookupError as e:
        return json_error(404, str(e.args[0]))
    if isinstance(result, Infeasible):
        return json_error(409, f"cannot recover {fields[1]}:\n{result}")
    return web.json_response({"plan": [result.epoch, result.version], "allocator": coord.name})


async def post_move(request: web.Request) -> web.Response:
    """POST /v1/move {component, to?} (token): a planned move of the component's active, to
    robot `to` or, without it, to wherever the allocation puts it off its current robot."""
    body = await _body(request)
    coord = _coord(request)
    component, to = body.get("component"), body.get("to")
    if not isinstance(component, str) or not component:
        return json_error(400, "field 'component': a component name is required")
    if to is not None and not isinstance(to, str):
        return json_error(400, "field 'to': a robot name, or absent")
    try:
        result = await coord.move_component(component, to or None)
    except NotAllocator as e:
        return await _forward(request, e.leader, body)
    except MoveError as e:
        return json_error(409, f"cannot move {component}: {e}")
    if isinstance(result, Infeasible):
        return json_error(409, f"cannot move {component}:\n{result}")
    active = result.active_of(component)
    return web.json_response(
        {
            "plan": result.to_json(),
            "allocator": coord.name,
            "robot": None if active is None else active.robot,
            "instance": None if active is None else active.instance,
        }
    )


async def post_state(request: web.Request) -> web.Response:
    """POST /v1/state (token; a msgpack StateMsg): a component's state for an instance here."""
    handoff = _coord(request).handoff
    limit = MAX_STATE + 64 * 1024
    if request.content_length is not None and request.content_length > limit:
        handoff.counters["dropped_oversized"] += 1
        return json_error(413, f"a state message may take at most {limit} bytes")
    data = bytearray()
    async for chunk in request.content.iter_any():
        data += chunk
        if len(data) > limit:
            handoff.counters["dropped_oversized"] += 1
            return json_error(413, f"a state message may take at most {limit} bytes")
    try:
        msg = StateMsg.decode(bytes(data))
    except ValueError as e:
        handoff.counters["dropped_malformed"] += 1
        return json_error(400, f"not a state message: {e}")
    verdict = handoff.receive(msg)
    return web.json_response({"verdict": verdict}, status=200 if verdict in (APPLY, HOLD) else 409)


ROUTES = [
    Route("POST", "/v1/deploy", post_deploy),
    Route("POST", "/v1/undeploy", post_undeploy),
    Route("GET", "/v1/status", get_status),
    Route("GET", "/v1/describe/{name}", get_describe),
    Route("GET", "/v1/plan", get_plan),
    Route("POST", "/v1/plan", post_plan),
    Route("POST", "/v1/recovery", post_recovery),
    Route("POST", "/v1/move", post_move),
    Route("POST", "/v1/state", post_state),
]
