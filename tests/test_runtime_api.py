"""The /v1/instances routes over a real InstanceManager running fake hosts: tokens, validation,
convergence with a connection, actions, logs (tail and follow), removal."""

from __future__ import annotations

import asyncio
import sys
from collections.abc import AsyncIterator
from pathlib import Path
from typing import Any

import pytest
from aiohttp.test_utils import TestClient, TestServer

from sdrpeer.api.app import build_app
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.vocabulary import LifecycleState
from tests.wait import until_answer

TOKEN = "tok"
AUTH = {"Authorization": f"Bearer {TOKEN}"}
FAKE_HOST = str(Path(__file__).with_name("fake_host.py"))
WAIT = 10.0


WITH_EXEC = LaunchPolicy(("python", "exec"))
"""The fake hosts are run by the exec launcher, off by default."""


class View:
    """Just enough of an agent: a name and an instance manager."""

    def __init__(self, manager: InstanceManager | None) -> None:
        self.instances = manager
        self.name = "robot-1"

    def members_view(self) -> list[dict[str, Any]]:
        return []

    def agent_view(self) -> dict[str, Any]:
        return {}

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        return []

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        return {}


def fake(name: str, *conns: dict[str, Any], mode: str = "") -> dict[str, Any]:
    argv = [sys.executable, FAKE_HOST, f"--mode={mode}"]
    return {"name": name, "launcher": "exec", "target": argv, "connections": list(conns)}


@pytest.fixture
async def setup(tmp_path: Path) -> AsyncIterator[tuple[TestClient[Any, Any], InstanceManager]]:
    manager = InstanceManager(tmp_path, supervisor_fast(), interval=0.1, policy=WITH_EXEC)
    await manager.start()
    client = TestClient(TestServer(build_app(View(manager), token=TOKEN)))
    await client.start_server()
    try:
        yield client, manager
    finally:
        await client.close()
        await asyncio.wait_for(manager.stop(), 10)


async def states(client: TestClient[Any, Any]) -> dict[str, str]:
    resp = await client.get("/v1/instances")
    assert resp.status == 200
    return {i["name"]: i["state"] for i in await resp.json()}


async def test_writes_need_the_token(setup):
    client, _ = setup
    body = {"instances": [fake("A")]}
    for method, path in [
        ("POST", "/v1/instances"),
        ("DELETE", "/v1/instances/A"),
        ("POST", "/v1/instances/A/activate"),
    ]:
        resp = await client.request(method, path, json=body)
        assert resp.status == 401, (method, path)
    assert (await client.get("/v1/instances")).status == 200


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({"instances": [{"name": "A", "target": "nocolon"}]}, "instances[0].target"),
        ({"instances": [fake("A"), {"name": "B bad", "target": "m:C"}]}, "instances[1].name"),
        ({"instances": [fake("A"), fake("A")]}, "instances[1].name"),
        ({"instances": [fake("A")], "replace": "yes"}, "replace"),
        ({"instances": [fake("A", {"out": "o", "to": "B", "in": "i", "policy": {"full": "x"}})]},
         "instances[0].connections[0].policy.full"),
    ],
)  # fmt: skip
async def test_validation_errors_name_the_field(setup, body, field):
    client, manager = setup
    resp = await client.post("/v1/instances", json=body, headers=AUTH)
    assert resp.status == 400
    assert f"field '{field}'" in (await resp.json())["error"]
    assert manager.desired() == {}


async def test_unknown_instance_and_action(setup):
    client, _ = setup
    assert (await client.post("/v1/instances/Z/activate", headers=AUTH)).status == 404
    assert (await client.delete("/v1/instances/Z", headers=AUTH)).status == 404
    assert (await client.get("/v1/instances/Z/logs")).status == 404
    resp = await client.post("/v1/instances/Z/dance", headers=AUTH)
    assert resp.status == 400


async def test_no_instance_manager_is_404(tmp_path):
    async with TestClient(TestServer(build_app(View(None), token=TOKEN))) as client:
        assert (await client.get("/v1/instances")).status == 404


async def test_converge_act_logs_and_remove(setup):
    client, manager = setup
    link = {"id": "c1", "out": "out", "to": "B", "in": "inp", "policy": {"buffer": 2}}
    body = {"instances": [fake("A", link), fake("B")], "replace": True}
    resp = await client.post("/v1/instances", json=body, headers=AUTH)
    assert resp.status == 200
    assert (await resp.json())["desired"] == ["A", "B"]
    await until_answer(
        "both ACTIVE", lambda: states(client), lambda s: s == {"A": "ACTIVE", "B": "ACTIVE"}
    )
    status = {i["name"]: i for i in await (await client.get("/v1/instances")).json()}
    a, b = status["A"], status["B"]
    assert a["connections"][0]["addr"] == f"unix://{b['data']['unix']}"
    assert a["connections"][0]["policy"] == {"buffer": 2}
    assert a["pid"] > 0
    assert a["start_latency_s"] > 0
    assert a["role"] == "active"
    # receivers before senders: B was activated before A
    log_a = await (await client.get("/v1/instances/A/logs", params={"tail": "50"})).text()
    assert "fake-host: got connect" in log_a
    assert log_a.index("got connect") < log_a.index("got activate")
    infos = manager.infos()
    assert [(i.name, i.state, i.role) for i in infos] == [
        ("A", LifecycleState.ACTIVE, "active"),
        ("B", LifecycleState.ACTIVE, "active"),
    ]

    resp = await client.post("/v1/instances/A/deactivate", headers=AUTH)
    assert resp.status == 200
    assert (await resp.json())["desired"] == "inactive"
    await until_answer("A INACTIVE", lambda: states(client), lambda s: s["A"] == "INACTIVE")
    resp = await client.post("/v1/instances/A/reset", headers=AUTH)
    assert resp.status == 200  # the fake host accepts reset in any state
    resp = await client.post("/v1/instances/B/restart", headers=AUTH)
    assert resp.status == 200
    await until_answer("B ACTIVE again", lambda: states(client), lambda s: s["B"] == "ACTIVE")
    b_again = next(i for i in await (await client.get("/v1/instances")).json() if i["name"] == "B")
    assert b_again["pid"] != b["pid"]
    new_addr = f"unix://{b_again['data']['unix']}"
    assert new_addr != a["connections"][0]["addr"]

    async def a_addr() -> str:
        listing = await (await client.get("/v1/instances")).json()
        return str(next(i for i in listing if i["name"] == "A")["connections"][0]["addr"])

    await until_answer("A repointed to B's new address", a_addr, lambda addr: addr == new_addr)
    assert "got repoint" in (await (await client.get("/v1/instances/A/logs")).text())

    resp = await client.delete("/v1/instances/B", headers=AUTH)
    assert resp.status == 200
    await until_answer("B gone", lambda: states(client), lambda s: "B" not in s)


async def test_logs_follow_streams_new_output(setup):
    client, _ = setup
    await client.post("/v1/instances", json={"instances": [fake("A")]}, headers=AUTH)
    await until_answer("A ACTIVE", lambda: states(client), lambda s: s.get("A") == "ACTIVE")
    resp = await client.get("/v1/instances/A/logs", params={"tail": "1", "follow": "1"})
    assert resp.status == 200
    first = await asyncio.wait_for(resp.content.readany(), WAIT)
    assert first
    await client.post("/v1/instances/A/deactivate", headers=AUTH)
    seen = b""
    async with asyncio.timeout(WAIT):
        while b"got deactivate" not in seen:
            seen += await resp.content.readany()
    resp.close()  # the client goes away; the handler notices and ends


async def test_a_starting_agent_answers_503_not_404(tmp_path):
    """An agent serves its API before its deployment stack has loaded: instance and deployment
    requests are 'try again' (503), not 'this agent has none' (404); /healthz says not ready."""
    from sdrpeer.deploy.routes import ROUTES as DEPLOY_ROUTES  # noqa: PLC0415

    view = View(None)
    view.ready = False  # type: ignore[attr-defined]
    view.coordinator = None  # type: ignore[attr-defined]
    app = build_app(view, token=TOKEN, extra_routes=DEPLOY_ROUTES)
    async with TestClient(TestServer(app)) as client:
        assert (await client.get("/v1/instances")).status == 503
        assert (await client.get("/v1/status")).status == 503
        assert (await (await client.get("/healthz")).json())["ready"] is False
        view.ready = True  # type: ignore[attr-defined]
        assert (await client.get("/v1/instances")).status == 404
        assert (await client.get("/v1/status")).status == 404


async def test_followed_logs_are_capped_and_a_slot_frees_when_a_follower_leaves(setup, monkeypatch):
    """Fails on the old code (no cap: the third follow was answered 200). A followed log holds a
    connection the API never sheds, and reading is open: uncapped, followers could hold all."""
    from sdrpeer.api import app as api_app  # noqa: PLC0415

    monkeypatch.setattr(api_app, "MAX_FOLLOWS", 2, raising=False)  # raising: the old code had none
    client, _ = setup
    await client.post("/v1/instances", json={"instances": [fake("A")]}, headers=AUTH)
    await until_answer("A ACTIVE", lambda: states(client), lambda s: s.get("A") == "ACTIVE")
    follow = {"tail": "1", "follow": "1"}
    held = [await client.get("/v1/instances/A/logs", params=follow) for _ in range(2)]
    assert [r.status for r in held] == [200, 200]
    over = await client.get("/v1/instances/A/logs", params=follow)
    assert over.status == 503
    assert await over.json() == {"error": "at most 2 logs followed at once"}
    plain = await client.get("/v1/instances/A/logs", params={"tail": "1"})
    assert plain.status == 200  # a tail without follow is not counted
    held[0].close()  # the follower goes away; its handler notices and ends

    async def again() -> int:
        resp = await client.get("/v1/instances/A/logs", params=follow)
        resp.close()
        status: int = resp.status
        return status

    await until_answer("a slot free again", again, lambda status: status == 200)
    held[1].close()
