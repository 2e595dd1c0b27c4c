"""Agent-to-agent HTTP calls: fetch a plan, push a plan, hand a system to the allocator.

How it works: agents authenticate to each other with a *peer token* derived from the cluster
key (`sdrpeer.keys.derive.peer_token`), so no per-agent API token has to be shared. Without a
key (`--insecure`) an insecure robot works alone: plans, recoveries and states do not travel
between robots. Each call has a short timeout and turns every failure into `ApiError`.
"""

from __future__ import annotations

from typing import Any

from sdrpeer.api.peer_client import call
from sdrpeer.errors import ApiError
from sdrpeer.plan import Plan, plan_from_json


async def fetch_plan(api: str, token: str) -> Plan:
    """The plan another agent holds (ApiError when it holds none)."""
    plan = await peer_plan(api, token)
    if plan is None:
        raise ApiError(f"{api}/v1/plan: it holds no plan")
    return plan


async def peer_plan(api: str, token: str) -> Plan | None:
    """The plan another agent holds, None when it holds none."""
    status, doc = await call(api, "GET", "/v1/plan", token)
    if status != 200 or not isinstance(doc, dict) or "plan" not in doc:
        raise ApiError(f"{api}/v1/plan: status {status}: {_error(doc)}")
    if doc["plan"] is None:
        return None
    try:
        return plan_from_json(doc["plan"])
    except ValueError as e:
        raise ApiError(f"{api}/v1/plan: {e}") from None


async def push_plan(api: str, token: str, plan: Plan) -> bool:
    """Offer a plan to another agent; True if it took it."""
    status, doc = await call(api, "POST", "/v1/plan", token, body={"plan": plan.to_json()})
    return status == 200 and isinstance(doc, dict) and bool(doc.get("accepted"))


def _error(doc: Any) -> str:
    if isinstance(doc, dict) and "error" in doc:
        return str(doc["error"])
    return "unexpected answer"
