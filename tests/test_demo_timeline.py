"""The timeline recorder against fake agents (http.server in threads), and load_timeline."""

from __future__ import annotations

import json
import threading
import time
import urllib.parse
from collections.abc import Iterator
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.demo.timeline import TimelineRecorder, load_timeline
from tests.test_demo_collect import member
from tests.wait import until

CAM = ("Cam-1", "Camera", "active", "active")
CAM_OFF = ("Cam-1", "Camera", "inactive", "active")


class FakeAgent:
    """Serves canned /v1/members and /v1/events answers that a test changes while it runs."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.members: list[dict[str, Any]] = []
        self.events: list[dict[str, Any]] = []
        agent = self

        class Handler(BaseHTTPRequestHandler):
            def do_GET(self) -> None:
                url = urllib.parse.urlsplit(self.path)
                query = dict(urllib.parse.parse_qsl(url.query))
                if url.path == "/v1/members":
                    body: Any = agent.members
                elif url.path == "/v1/events":
                    since, limit = int(query.get("since", 0)), int(query.get("limit", 500))
                    body = [e for e in agent.events if e["id"] > since][:limit]
                else:
                    self.send_error(404)
                    return
                data = json.dumps(body).encode()
                self.send_response(200)
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(data)))
                self.end_headers()
                self.wfile.write(data)

            def log_message(self, format: str, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.server.daemon_threads = True
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}"
        self._thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self._thread.start()
        self.alive = True

    def log(self, kind: str, robot: str | None = None, **detail: Any) -> None:
        eid = len(self.events) + 1
        entry = {"id": eid, "ts": round(time.time(), 3), "kind": kind, "robot": robot or self.name}
        self.events = [*self.events, entry | {"detail": detail}]

    def kill(self) -> None:
        if self.alive:
            self.alive = False
            self.server.shutdown()
            self.server.server_close()
            self._thread.join(5)


@pytest.fixture
def agents() -> Iterator[dict[str, FakeAgent]]:
    fakes = {name: FakeAgent(name) for name in ("robot-1", "robot-2")}
    yield fakes
    for fake in fakes.values():
        fake.kill()


def settle(rec: TimelineRecorder, rounds: int = 2) -> None:
    """Wait until `rounds` more poll rounds have been written (a condition, not a duration)."""
    target = rec.rounds + rounds
    until(
        f"{rounds} more poll rounds",
        lambda: rec.rounds,
        lambda n: n >= target,
        within=20,
        poll=0.01,
    )


def test_recorder_writes_samples_states_events_marks_and_survives_a_dead_agent(
    agents: dict[str, FakeAgent], tmp_path: Path
) -> None:
    r1, r2 = agents["robot-1"], agents["robot-2"]
    r1.members = [member("robot-1", mem_free=111, instances=(CAM_OFF,)), member("robot-2")]
    r2.members = [member("robot-1", mem_free=999, instances=(CAM,)), member("robot-2")]
    r1.log("election", epoch=1, leader="robot-1")
    r1.log("instance.state", instance="Cam-1")  # not a kind the timeline keeps
    r2.log("trap", "robot-1", metric="rssi")  # robot-1's trap as robot-2 heard it: dropped
    r2.log("member.alive", "robot-1")  # robot-1 answers, so it is the member source

    out = tmp_path / "demo" / "timeline.jsonl"
    rec = TimelineRecorder({"robot-1": r1.url, "robot-2": r2.url}, out, interval=0.02, timeout=10)
    rec.start()
    try:
        settle(rec)
        r1.members = [member("robot-1", mem_free=112, instances=(CAM,)), member("robot-2")]
        r1.log("allocation", reason="deploy", epoch=1)
        rec.mark("allocation", "deploy")
        settle(rec)
        r1.kill()
        rec.mark("fault", "robot-1 killed")
        dead = member("robot-1", state="dead", instances=(CAM,))
        r2.members = [dead, member("robot-2")]
        r2.log("member.dead", "robot-1")
        r2.log("recovery.started", cause="member_dead")
        settle(rec, 3)
    finally:
        rec.stop()
    rec.stop()  # twice is harmless
    rec.mark("recovery", "after stop")  # dropped, never raises

    lines = load_timeline(out)
    start = [x for x in lines if x["kind"] == "start"]  # events logged before it have t < 0
    assert [(x["t"], x["robots"]) for x in start] == [(0.0, ["robot-1", "robot-2"])]
    assert [x["t"] for x in lines] == sorted(x["t"] for x in lines)

    samples = [x for x in lines if x["kind"] == "sample" and x["robot"] == "robot-1"]
    assert {x["mem_free"] for x in samples} == {111, 112}  # robot-1's own view, never 999
    assert any(x["robot"] == "robot-2" for x in lines if x["kind"] == "sample")

    states = [
        (x["robot"], x["instance"], x["state"], x["via"]) for x in lines if x["kind"] == "state"
    ]
    assert states == [
        ("robot-1", "Cam-1", "inactive", "robot-1"),
        ("robot-1", "Cam-1", "active", "robot-1"),
        ("robot-1", "Cam-1", "gone", "robot-2"),
    ]

    events = [(x["robot"], x["event"], x["via"]) for x in lines if x["kind"] == "event"]
    assert sorted(events) == sorted(
        [
            ("robot-1", "election", "robot-1"),
            ("robot-1", "allocation", "robot-1"),
            ("robot-1", "member.dead", "robot-2"),
            ("robot-2", "recovery.started", "robot-2"),
        ]
    )
    marks = [(x["what"], x["label"]) for x in lines if x["kind"] == "mark"]
    assert marks == [("allocation", "deploy"), ("fault", "robot-1 killed")]

    health = [(x["robot"], x["status"]) for x in lines if x["kind"] == "agent"]
    assert health.count(("robot-1", "down")) == 1
    assert ("robot-2", "down") not in health
    down = next(x for x in lines if x["kind"] == "agent" and x["status"] == "down")
    assert "cannot reach agent" in down["error"]


def test_recorder_with_no_agent_answering_still_stops(tmp_path: Path) -> None:
    out = tmp_path / "timeline.jsonl"
    with TimelineRecorder({"robot-9": "http://127.0.0.1:9"}, out, interval=0.01) as rec:
        settle(rec, 1)
    kinds = [x["kind"] for x in load_timeline(out)]
    assert kinds == ["start", "agent"]


def test_load_timeline_skips_torn_lines_and_sorts(tmp_path: Path) -> None:
    path = tmp_path / "timeline.jsonl"
    path.write_text(
        '{"t": 0.0, "kind": "start"}\n'
        '{"t": 2.5, "kind": "mark", "what": "recovery", "label": ""}\n'
        '{"t": 1.0, "kind": "sample", "robot": "robot-1"}\n'
        "[1, 2]\n"
        '{"kind": "no t"}\n'
        '{"t": 3.0, "kind": "ev'
    )
    assert [x["t"] for x in load_timeline(path)] == [0.0, 1.0, 2.5]
