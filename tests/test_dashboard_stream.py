"""The dashboard's HTTP side: the page and its vendored files, /v1/history, and the live stream
(contents, order, replay after a reconnect, slow and surplus clients)."""

from __future__ import annotations

import asyncio
import json
import re
import time
from collections.abc import AsyncIterator
from typing import Any

import aiohttp
import pytest
from aiohttp.test_utils import TestClient, TestServer

from sdrpeer.api.app import build_app
from sdrpeer.dashboard.feed import Feed
from sdrpeer.dashboard.routes import ROUTES
from sdrpeer.dashboard.stream import Hub
from sdrpeer.eventlog import EventLog
from tests.test_dashboard_history import STATUS, member


class Source:
    """A DashboardSource and AgentView with an event log and a status."""

    def __init__(self) -> None:
        self.events = EventLog()
        self.status: dict[str, Any] | None = STATUS
        self.fleet = [member("r1", typical={"rtt_ms": 2.0, "jitter_ms": 0.4, "loss": 0.05})]
        self.dashboard = Feed(self, hub=Hub(max_clients=2, queue_len=8, keepalive_s=0.2))
        self.events.listeners.append(self.dashboard.on_event)

    @property
    def name(self) -> str:
        return "r1"

    def members_view(self) -> list[dict[str, Any]]:
        return self.fleet

    def agent_view(self) -> dict[str, Any]:
        return {}

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        return self.events.since(since, limit)

    def status_view(self) -> dict[str, Any] | None:
        return self.status

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        return {}


@pytest.fixture
async def client() -> AsyncIterator[tuple[TestClient[Any, Any], Source]]:
    source = Source()
    app = build_app(source, token="t", extra_routes=ROUTES)
    async with TestClient(TestServer(app)) as c:
        yield c, source
    source.dashboard.close()


async def read_events(resp: aiohttp.ClientResponse, n: int) -> list[tuple[str, str | None, Any]]:
    """The next `n` SSE messages as (event, id, data); comments and retry lines skipped."""
    out: list[tuple[str, str | None, Any]] = []
    kind, ident, data = "message", None, ""
    async with asyncio.timeout(5):
        while len(out) < n:
            line = (await resp.content.readline()).decode()
            assert line, "the stream ended"
            line = line.rstrip("\n")
            if not line:
                if data:
                    out.append((kind, ident, json.loads(data)))
                kind, ident, data = "message", None, ""
            elif line.startswith("event: "):
                kind = line[7:]
            elif line.startswith("id: "):
                ident = line[4:]
            elif line.startswith("data: "):
                data += line[6:]
    return out


async def test_a_new_page_gets_hello_history_events_and_a_sample_in_that_order(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    source.events.add(1.0, "member.join", "r2")
    source.events.add(2.0, "trap", "r1", metric="rssi")
    source.dashboard.tick(10.0)
    resp = await c.get("/v1/stream")
    assert resp.headers["Content-Type"] == "text/event-stream"
    (k1, _, hello), (k2, _, history), (k3, id3, events), (k4, _, sample) = await read_events(
        resp, 4
    )
    assert (k1, k2, k3, k4) == ("hello", "history", "events", "sample")
    assert hello == {"robot": "r1", "window_s": 900.0, "interval_s": 1.0}
    assert history["t"] == [10.0]
    assert history["robots"]["r1"]["rtt_ms"] == [2.0]
    assert [m["kind"] for m in history["moments"]] == ["allocation", "state", "state", "component"]
    assert [e["kind"] for e in events] == ["member.join", "trap"]
    assert id3 == "2"  # the page resumes from here after a reconnect
    (row,) = sample["members"]
    assert row["link"] == {"peers": 2, "rtt_ms": 2.0, "jitter_ms": 0.4, "loss": 0.05}
    assert sample["status"]["allocator"]["name"] == "r2"
    # then, live and in order: events as they are logged, samples as they are taken
    source.events.add(3.0, "election", "r1", epoch=2)
    source.status = {**STATUS, "allocator": {"name": "r1", "epoch": 2}}
    source.dashboard.tick(11.0)
    source.events.add(4.0, "recovery.move", "r1", moved={"Cam": ["r1", "r2"]})
    live = await read_events(resp, 3)
    assert [(k, i) for k, i, _ in live] == [("event", "3"), ("sample", None), ("event", "4")]
    assert live[1][2]["moments"] == [{"ts": 11.0, "kind": "election", "leader": "r1", "epoch": 2}]
    resp.close()


async def test_a_reconnecting_page_gets_only_the_events_it_missed(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    for i in range(5):
        source.events.add(float(i), "trap", "r1", n=i)
    resp = await c.get("/v1/stream", headers={"Last-Event-ID": "3"})
    _, _, (_, ident, events), _ = await read_events(resp, 4)
    assert [e["detail"]["n"] for e in events] == [3, 4]
    assert ident == "5"
    resp.close()


async def test_a_slow_page_is_dropped_and_others_keep_going(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    hub = source.dashboard.hub
    resp = await c.get("/v1/stream")
    await read_events(resp, 4)
    assert hub.clients == 1
    for i in range(50):  # the queue holds 8: publishing never blocks, the reader falls behind
        source.events.add(float(i), "trap", "r1", n=i)
    assert hub.counters["dropped_clients"] == 1
    assert hub.clients == 0
    got = await read_events(resp, 8)  # what was queued before the drop, then the end
    assert [d["detail"]["n"] for _, _, d in got] == list(range(8))
    async with asyncio.timeout(5):
        assert await resp.content.read() == b""  # closed: the browser reconnects and catches up


async def test_streams_are_capped_and_keepalives_flow(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    first = await c.get("/v1/stream")
    second = await c.get("/v1/stream")
    third = await c.get("/v1/stream")
    assert (first.status, second.status, third.status) == (200, 200, 503)
    assert source.dashboard.hub.counters["refused_clients"] == 1
    await read_events(first, 4)
    async with asyncio.timeout(3):
        while (await first.content.readline()) != b": keepalive\n":
            pass
    first.close()
    second.close()


async def test_page_files_and_history(client: tuple[TestClient[Any, Any], Source]) -> None:
    c, source = client
    page = await c.get("/")
    assert page.status == 200
    text = await page.text()
    assert "/dashboard/uPlot.iife.min.js" in text
    assert not re.search(r"(src|href)=\"(https?:)?//", text)  # nothing from outside the agent
    for name, kind in [
        ("dashboard.js", "text/javascript"),
        ("dashboard.css", "text/css"),
        ("uPlot.iife.min.js", "text/javascript"),
        ("uPlot.min.css", "text/css"),
        ("uPlot.LICENSE.txt", "text/plain"),
    ]:
        resp = await c.get(f"/dashboard/{name}")
        assert (resp.status, resp.content_type) == (200, kind), name
    for bad in ("nope.js", "..%2Froutes.py", "feed.py", "%2E%2E%2F%2E%2E%2Fagent.py"):
        assert (await c.get(f"/dashboard/{bad}")).status == 404, bad
    source.dashboard.tick(5.0)
    source.dashboard.tick(6.0)
    doc = await (await c.get("/v1/history?since=5.5")).json()
    assert doc["t"] == [6.0]
    assert (await c.get("/v1/history?since=yesterday")).status == 400


async def test_a_state_change_brings_a_fresh_sample_without_waiting_for_the_tick(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    source.dashboard.tick(1.0)
    resp = await c.get("/v1/stream")
    await read_events(resp, 4)
    (cam,) = STATUS["components"]
    assert isinstance(cam, dict)
    source.status = {**STATUS, "components": [{**cam, "state": "error"}]}
    for _ in range(3):  # several changes at once make one sample
        source.events.add(1.0, "instance.state", "r1", instance="Cam", state="error")
    source.events.add(2.0, "trap", "r1")  # not a change the pages draw: no sample of its own
    got = await read_events(resp, 5)
    assert [k for k, _, _ in got] == ["event", "event", "event", "event", "sample"]
    moments = got[-1][2]["moments"]
    assert [(m["kind"], m["instance"], m["state"]) for m in moments] == [
        ("state", "Cam", "error"),
        ("component", "Cam", "error"),
    ]
    resp.close()


async def test_once_sends_what_a_new_page_gets_then_ends(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    source.events.add(1.0, "member.join", "r2")
    resp = await c.get("/v1/stream?once=1")
    got = await read_events(resp, 5)
    assert [k for k, _, _ in got] == ["hello", "history", "events", "sample", "end"]
    async with asyncio.timeout(5):
        assert await resp.content.read() == b""  # the response is over: nothing keeps a page
    assert source.dashboard.hub.clients == 0  # and it never counted as a live stream
    source.events.add(2.0, "trap", "r1")  # nothing to publish to


async def test_a_sample_keeps_a_reaped_robot_and_carries_the_warnings(
    client: tuple[TestClient[Any, Any], Source],
) -> None:
    c, source = client
    (cam,) = STATUS["components"]
    assert isinstance(cam, dict)
    source.status = {
        **STATUS,
        "components": [{**cam, "instance": "Cam-s1", "standbys": [], "standbys_wanted": 1}],
        "connections": [{"from": "Cam.image", "to": "Det.image", "lost_per_s": 12}],
    }
    died = time.time() - 20  # the page's sample is taken now, in wall time
    source.fleet = [member("r1"), {**member("r2", state="dead"), "since": died}]
    source.dashboard.tick(died + 1)
    source.fleet = [member("r1")]  # gossip reaped r2
    source.dashboard.tick(died + 11)
    resp = await c.get("/v1/stream?once=1")
    *_, (_, _, sample), _ = await read_events(resp, 5)
    r1, r2 = sample["members"]
    assert (r1["name"], "dead_since" in r1) == ("r1", False)
    assert (r2["name"], r2["state"], r2["dead_since"], r2["reaped"]) == ("r2", "dead", died, True)
    assert sample["status"]["components"][0]["was_standby"] is True
    assert [(w["kind"], w["subject"]) for w in sample["warnings"]] == [
        ("no_standby", "Cam"),
        ("dropping_frames", "Cam.image → Det.image"),
    ]
