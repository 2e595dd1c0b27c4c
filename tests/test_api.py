"""HTTP API against a fake AgentView: auth, JSON errors, query validation, Prometheus text."""

from __future__ import annotations

from collections.abc import AsyncIterator
from typing import Any

import pytest
from aiohttp import web
from aiohttp.test_utils import TestClient, TestServer
from prometheus_client.parser import text_string_to_metric_families

from sdrpeer.api.app import Route, add_routes, build_app, require_token
from sdrpeer.errors import ConfigError

TOKEN = "s3cret-token"
AUTH = {"Authorization": f"Bearer {TOKEN}"}


class FakeView:
    """An AgentView with canned data that records set_virtual calls."""

    def __init__(self) -> None:
        self.changes: list[dict[str, Any]] = []
        self.event_calls: list[tuple[int, int]] = []

    @property
    def name(self) -> str:
        return "robot-1"

    def members_view(self) -> list[dict[str, Any]]:
        return [
            {
                "name": "robot-1",
                "addr": "127.0.0.1:7946",
                "state": "alive",
                "incarnation": 0,
                "since": 1700000000.0,
                "api": "http://127.0.0.1:8080",
                "record_version": 3,
                "metrics": {
                    "cpu_pct": 12.5,
                    "mem_total": 4_000_000_000,
                    "mem_free": 3_200_000_000,
                    "battery_pct": 87.0,
                    "rssi_dbm": -47.0,
                    "pos": [0.0, 0.0],
                },
                "links": {"robot-2": {"rtt_ms": 0.4, "jitter_ms": 0.1, "loss": 0.0}},
                "link_summary": {
                    "peers": 1,
                    "typical": {"rtt_ms": 0.4, "jitter_ms": 0.1, "loss": 0.0},
                    "bad": 0,
                    "listed": {},
                },
            },
            {
                "name": "robot-2",
                "addr": "127.0.0.1:7947",
                "state": "suspect",
                "incarnation": 2,
                "since": 1700000001.0,
                "api": None,
                "record_version": 1,
                "metrics": None,
                "links": {},
            },
        ]

    def agent_view(self) -> dict[str, Any]:
        return {
            "name": "robot-1",
            "addr": "127.0.0.1:7946",
            "api": "http://127.0.0.1:8080",
            "version": "0.1.0",
            "uptime_s": 12.0,
            "insecure": False,
            "preset": "lan",
            "health_score": 1,
            "messages": {
                "in": 10,
                "out": 11,
                "bytes_in": 1000,
                "bytes_out": 1100,
                "bytes_in_per_s": 50.0,
                "bytes_out_per_s": 55.0,
            },
            "rejected": {"bad_mac": 2},
            "api_connections": {
                "open": 3,
                "refused": 0,
                "shed": 5,
                "idle_closed": 1,
                "header_closed": 2,
            },
            "members": {"alive": 1, "suspect": 1, "dead": 0, "left": 0},
        }

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        self.event_calls.append((since, limit))
        return [
            {"id": i, "ts": 1700000000.0 + i, "kind": "member.join", "robot": "r", "detail": {}}
            for i in range(since + 1, 6)
        ][:limit]

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        if "warp" in changes:
            raise ConfigError("warp: unknown robot field")
        self.changes.append(changes)
        return {"battery_pct": 30.0}


@pytest.fixture
def view() -> FakeView:
    return FakeView()


@pytest.fixture
async def client(view: FakeView) -> AsyncIterator[TestClient[web.Request, web.Application]]:
    async with TestClient(TestServer(build_app(view, token=TOKEN))) as client:
        yield client


async def test_reads_are_open(client: TestClient[web.Request, web.Application]) -> None:
    for path in ("/v1/members", "/v1/agent", "/v1/events", "/healthz", "/metrics"):
        response = await client.get(path)
        assert response.status == 200, path
    members = await (await client.get("/v1/members")).json()
    assert [m["name"] for m in members] == ["robot-1", "robot-2"]
    healthz = await (await client.get("/healthz")).json()
    assert healthz == {"status": "ok", "name": "robot-1", "ready": True}


async def test_post_robot_needs_the_token(
    client: TestClient[web.Request, web.Application], view: FakeView
) -> None:
    body = {"battery": "30%"}
    missing = await client.post("/v1/robot", json=body)
    assert missing.status == 401
    assert "token" in (await missing.json())["error"]
    wrong = await client.post("/v1/robot", json=body, headers={"Authorization": "Bearer nope"})
    assert wrong.status == 401
    basic = await client.post("/v1/robot", json=body, headers={"Authorization": f"Basic {TOKEN}"})
    assert basic.status == 401
    assert view.changes == []
    ok = await client.post("/v1/robot", json=body, headers=AUTH)
    assert ok.status == 200
    assert await ok.json() == {"name": "robot-1", "metrics": {"battery_pct": 30.0}}
    assert view.changes == [body]


@pytest.mark.parametrize(
    ("body", "message"),
    [
        (b"{not json", "body is not JSON"),
        (b"[1, 2]", "body must be a JSON object"),
        (b"{}", "body must be a non-empty JSON object"),
        (b'{"warp": 9}', "warp: unknown robot field"),
        (b'{"rssi": "-80dBm\xff"}', "body is not UTF-8 text"),
        (b"[" * 100_000 + b"]" * 100_000, "body is not JSON"),
    ],
)
async def test_post_robot_bad_body_is_400(
    client: TestClient[web.Request, web.Application], body: bytes, message: str
) -> None:
    response = await client.post("/v1/robot", data=body, headers=AUTH)
    assert response.status == 400
    assert message in (await response.json())["error"]


async def test_events_query(
    client: TestClient[web.Request, web.Application], view: FakeView
) -> None:
    events = await (await client.get("/v1/events?since=3&limit=1")).json()
    assert [e["id"] for e in events] == [4]
    assert view.event_calls == [(3, 1)]


@pytest.mark.parametrize(
    ("query", "message"),
    [
        ("since=abc", "since must be an integer, got 'abc'"),
        ("since=-1", "since must be in 0.."),
        ("limit=0", "limit must be in 1..10000, got 0"),
        ("limit=2.5", "limit must be an integer, got '2.5'"),
    ],
)
async def test_events_bad_query_is_400(
    client: TestClient[web.Request, web.Application], query: str, message: str
) -> None:
    response = await client.get(f"/v1/events?{query}")
    assert response.status == 400
    assert message in (await response.json())["error"]


async def test_unknown_route_is_json_404(
    client: TestClient[web.Request, web.Application],
) -> None:
    response = await client.get("/v1/nope")
    assert response.status == 404
    assert await response.json() == {"error": "Not Found"}
    wrong_method = await client.get("/v1/robot")
    assert wrong_method.status == 405
    assert "error" in await wrong_method.json()


async def test_added_routes_follow_the_token_rules(view: FakeView) -> None:
    @require_token
    async def secret(request: web.Request) -> web.Response:
        return web.json_response({"secret": 1})

    async def deploy(request: web.Request) -> web.Response:
        return web.json_response({"deployed": True})

    app = build_app(view, token=TOKEN)
    add_routes(app, [Route("GET", "/v1/secret", secret), Route("PUT", "/v1/deploy", deploy)])
    async with TestClient(TestServer(app)) as client:
        assert (await client.get("/v1/secret")).status == 401
        assert (await client.get("/v1/secret", headers=AUTH)).status == 200
        assert (await client.put("/v1/deploy")).status == 401
        assert (await client.put("/v1/deploy", headers=AUTH)).status == 200


def test_empty_token_is_refused(view: FakeView) -> None:
    with pytest.raises(ValueError, match="token must not be empty"):
        build_app(view, token="")


EXPECTED_FAMILIES = {
    "sdrpeer_member_up": "gauge",
    "sdrpeer_robot_cpu_ratio": "gauge",
    "sdrpeer_robot_memory_free_bytes": "gauge",
    "sdrpeer_robot_memory_total_bytes": "gauge",
    "sdrpeer_robot_battery_ratio": "gauge",
    "sdrpeer_robot_rssi_dbm": "gauge",
    "sdrpeer_robot_link_rtt_seconds": "gauge",
    "sdrpeer_robot_link_jitter_seconds": "gauge",
    "sdrpeer_robot_link_loss_ratio": "gauge",
    "sdrpeer_link_rtt_seconds": "gauge",
    "sdrpeer_link_jitter_seconds": "gauge",
    "sdrpeer_link_loss_ratio": "gauge",
    "sdrpeer_gossip_messages": "counter",
    "sdrpeer_gossip_bytes": "counter",
    "sdrpeer_gossip_rejected": "counter",
    "sdrpeer_api_connections": "gauge",
    "sdrpeer_api_connections_closed": "counter",
    "sdrpeer_members": "gauge",
    "sdrpeer_health_score": "gauge",
    "sdrpeer_uptime_seconds": "gauge",
    "sdrpeer_instance_state": "gauge",
    "sdrpeer_instance_sent_bytes_per_second": "gauge",
    "sdrpeer_instance_lost_frames_per_second": "gauge",
}


async def test_metrics_families_types_and_values(
    client: TestClient[web.Request, web.Application],
) -> None:
    response = await client.get("/metrics")
    assert response.headers["Content-Type"].startswith("text/plain; version=0.0.4")
    families = {f.name: f for f in text_string_to_metric_families(await response.text())}
    assert {name: f.type for name, f in families.items()} == EXPECTED_FAMILIES

    def samples(family: str) -> dict[tuple[tuple[str, str], ...], float]:
        return {tuple(sorted(s.labels.items())): s.value for s in families[family].samples}

    assert samples("sdrpeer_member_up") == {
        (("robot", "robot-1"), ("state", "alive")): 1.0,
        (("robot", "robot-2"), ("state", "suspect")): 0.0,
    }
    assert samples("sdrpeer_robot_cpu_ratio") == {(("robot", "robot-1"),): 0.125}
    assert samples("sdrpeer_robot_memory_free_bytes") == {(("robot", "robot-1"),): 3.2e9}
    assert samples("sdrpeer_robot_battery_ratio") == {(("robot", "robot-1"),): 0.87}
    assert samples("sdrpeer_robot_rssi_dbm") == {(("robot", "robot-1"),): -47.0}
    rtt = samples("sdrpeer_link_rtt_seconds")
    assert rtt[(("peer", "robot-2"), ("robot", "robot-1"))] == pytest.approx(0.0004)
    typical = samples("sdrpeer_robot_link_rtt_seconds")
    assert typical == {(("robot", "robot-1"),): pytest.approx(0.0004)}
    assert samples("sdrpeer_gossip_messages") == {
        (("direction", "in"),): 10.0,
        (("direction", "out"),): 11.0,
    }
    assert samples("sdrpeer_gossip_bytes")[(("direction", "out"),)] == 1100.0
    assert samples("sdrpeer_gossip_rejected") == {(("reason", "bad_mac"),): 2.0}
    assert samples("sdrpeer_api_connections") == {(): 3.0}
    assert samples("sdrpeer_api_connections_closed") == {
        (("reason", "refused"),): 0.0,
        (("reason", "shed"),): 5.0,
        (("reason", "idle_closed"),): 1.0,
        (("reason", "header_closed"),): 2.0,
    }
    assert samples("sdrpeer_members")[(("state", "suspect"),)] == 1.0
    assert samples("sdrpeer_health_score") == {(): 1.0}
    assert samples("sdrpeer_uptime_seconds") == {(): 12.0}


async def test_a_400_about_huge_input_shows_its_start_and_length(
    client: TestClient[web.Request, web.Application],
) -> None:
    response = await client.get("/v1/events?since=" + "x" * 5000)
    assert response.status == 400
    assert (await response.json())["error"] == (
        f"since must be an integer, got '{'x' * 60}'... (5,000 characters)"
    )
