"""`sdrpeer status` and `sdrpeer top` output: snapshots (plain and coloured), the stream reader,
and `top` against a live stream."""

from __future__ import annotations

import io
import threading
from collections.abc import Iterator
from typing import Any

import pytest
from aiohttp import web

from sdrpeer.api.app import build_app
from sdrpeer.cli.status import format_status, format_top
from sdrpeer.cli.top import read_stream, run_top
from sdrpeer.dashboard.routes import ROUTES
from tests.test_dashboard_stream import Source

DOC: dict[str, Any] = {
    "allocator": {"name": "robot-3", "epoch": 2},
    "plan": {"epoch": 2, "version": 5, "allocator": "robot-3", "system": "paper-demo"},
    "components": [
        {
            "component": "CameraRTC",
            "instance": "CameraRTC",
            "robot": "robot-2",
            "state": "active",
            "since": 1700000000.0,
            "standbys": [
                {"instance": "CameraRTC-s1", "robot": "robot-3", "state": "inactive", "mode": "hot"}
            ],
        },
        {
            "component": "AnomalyDetectionRTC",
            "instance": "AnomalyDetectionRTC-s1",
            "robot": "robot-3",
            "state": "error",
            "since": 1700000065.5,
            "standbys": [{"instance": "A-s2", "robot": "robot-1", "state": "cold", "mode": "cold"}],
        },
        {"component": "PositionEstimationRTC", "state": "unplaced", "standbys": []},
    ],
    "connections": [
        {
            "from": "CameraRTC.image",
            "to": "AnomalyDetectionRTC.image",
            "bytes_per_s": 194000,
            "lost_per_s": 37,
        },
        {"from": "AnomalyDetectionRTC.alarm", "to": "PositionEstimationRTC.alarm"},
    ],
}
STATUS_TEXT = """\
allocator: robot-3 (epoch 2)
system: paper-demo  plan 2.5 by robot-3
COMPONENT              ROBOT    STATE     SINCE     SENDS      STANDBYS
CameraRTC              robot-2  active    22:13:20  194.0KB/s  robot-3:inactive
AnomalyDetectionRTC    robot-3  error     22:14:25  -          robot-1:cold
PositionEstimationRTC  -        unplaced  -         -          -

FROM                       TO                           TRAFFIC    LOST
CameraRTC.image            AnomalyDetectionRTC.image    194.0KB/s  37/s
AnomalyDetectionRTC.alarm  PositionEstimationRTC.alarm  -          -"""


def test_status_snapshot_plain() -> None:
    assert format_status(DOC, local=False) == STATUS_TEXT


def test_status_colours_states_and_keeps_the_columns() -> None:
    text = format_status(DOC, color=True, local=False)
    assert "\x1b[32mactive\x1b[0m    22:13:20" in text  # padded by its visible width
    assert "\x1b[31merror\x1b[0m" in text
    assert "robot-3:\x1b[36minactive\x1b[0m" in text
    plain = text.replace("\x1b[32m", "").replace("\x1b[31m", "").replace("\x1b[36m", "")
    assert plain.replace("\x1b[90m", "").replace("\x1b[0m", "") == STATUS_TEXT


def test_a_sender_whose_receiver_refuses_it_gets_a_line_under_the_connections() -> None:
    conns = [{**DOC["connections"][0], "refused": 1}, {**DOC["connections"][1], "refused": 0}]
    text = format_status({**DOC, "connections": conns}, local=False)
    assert text == STATUS_TEXT + (
        "\nCameraRTC: 1 connection(s) refused by the receiver (sdrpeer describe CameraRTC)"
    )


def test_status_without_a_plan() -> None:
    doc: dict[str, Any] = {"allocator": {"name": None, "epoch": 0}, "plan": None, "components": []}
    assert format_status(doc) == "allocator: (none yet) (epoch 0)\nno system deployed"


SAMPLE: dict[str, Any] = {
    "ts": 1700000100.0,
    "robot": "robot-1",
    "status": DOC,
    "members": [
        {
            "name": "robot-1",
            "state": "alive",
            "metrics": {
                "cpu_pct": 12.5,
                "mem_free": 1_500_000_000,
                "battery_pct": 80.0,
                "rssi_dbm": -47.0,
            },
            "link": {"peers": 2, "rtt_ms": 0.42, "jitter_ms": 0.1, "loss": 0.0},
        },
        {"name": "robot-3", "state": "suspect", "metrics": None, "link": {"peers": 0}},
    ],
}
TOP_HEAD = """\
sdrpeer top — robot-1 at 22:15:00  ·  2 robots  ·  allocator robot-3

ROBOT    STATE    ROLE       CPU  MEM-FREE  BATTERY  RSSI      RTT    LOSS
robot-1  alive               12%  1.5GB     80%      -47.0dBm  0.4ms  0%
robot-3  suspect  allocator  -    -         -        -         -      -

"""


def test_top_snapshot() -> None:
    assert format_top(SAMPLE, local=False) == TOP_HEAD + STATUS_TEXT


def test_read_stream_parses_events_and_skips_comments() -> None:
    raw = (
        b"retry: 2000\n\n"
        b'event: hello\ndata: {"robot": "r1"}\n\n'
        b": keepalive\n\n"
        b'event: sample\nid: 7\ndata: {"ts": 1}\n\n'
        b"data: [1,\ndata: 2]\n\n"
    )
    assert list(read_stream(io.BytesIO(raw))) == [
        ("hello", {"robot": "r1"}),
        ("sample", {"ts": 1}),
        ("message", [1, 2]),
    ]


@pytest.fixture
def live_api() -> Iterator[tuple[str, Source]]:
    """The dashboard routes of a Source, served on loopback from a thread (top is synchronous)."""
    import asyncio  # noqa: PLC0415 - only this fixture runs a loop of its own

    source = Source()
    loop = asyncio.new_event_loop()
    ready, stop = threading.Event(), threading.Event()
    where: list[str] = []

    async def serve() -> web.AppRunner:
        runner = web.AppRunner(build_app(source, token="t", extra_routes=ROUTES))
        await runner.setup()
        site = web.TCPSite(runner, "127.0.0.1", 0)
        await site.start()
        port = runner.addresses[0][1]
        where.append(f"http://127.0.0.1:{port}")
        return runner

    def main() -> None:
        asyncio.set_event_loop(loop)
        runner = loop.run_until_complete(serve())

        async def ticks() -> None:
            for i in range(200):  # bounded: at most 20 s of samples
                if stop.is_set():
                    break
                source.dashboard.tick(1700000100.0 + i)
                await asyncio.sleep(0.1)

        task = loop.create_task(ticks())
        ready.set()
        loop.run_until_complete(task)
        source.dashboard.close()
        loop.run_until_complete(runner.cleanup())

    thread = threading.Thread(target=main, daemon=True)
    thread.start()
    assert ready.wait(5)
    yield where[0], source
    stop.set()
    thread.join(30)


def test_top_draws_screens_from_the_live_stream(live_api: tuple[str, Source]) -> None:
    api, _ = live_api
    out = io.StringIO()
    assert run_top(api, iterations=3, reconnect_s=5, out=out) == 0
    screens = out.getvalue().split("\n\nsdrpeer top")
    assert len(screens) == 3
    assert "\x1b[" not in out.getvalue()  # not a terminal: plain, appended
    assert "r1     active" in screens[-1]
    assert "allocator: r2 (epoch 1)" in screens[-1]
