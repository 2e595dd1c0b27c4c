"""Text rendering of the CLI: literal snapshots, human units, colour on and off."""

from __future__ import annotations

from datetime import UTC
from typing import Any

import pytest

from sdrpeer.cli.format import (
    format_agent,
    format_event,
    format_link,
    format_members,
    format_metrics,
    human_bytes,
    human_dbm,
    human_ms,
    human_seconds,
    render_table,
    visible_len,
    want_color,
)

MEMBERS: list[dict[str, Any]] = [
    {
        "name": "robot-1",
        "addr": "127.0.0.1:7946",
        "state": "alive",
        "incarnation": 0,
        "metrics": {
            "cpu_pct": 12.4,
            "mem_total": 4_000_000_000,
            "mem_free": 3_200_000_000,
            "battery_pct": 87.0,
            "rssi_dbm": -47.0,
            "pos": [0.0, 0.0],
        },
        "links": {
            "robot-3": {"rtt_ms": 12.34, "jitter_ms": 2.0, "loss": 0.25},
            "robot-2": {"rtt_ms": 0.42, "jitter_ms": 0.1, "loss": 0.0},
        },
        "link_summary": {
            "peers": 2,
            "typical": {"rtt_ms": 0.42, "jitter_ms": 0.1, "loss": 0.0},
            "bad": 1,
            "listed": {"robot-3": {"rtt_ms": 12.34, "jitter_ms": 2.0, "loss": 0.25}},
        },
    },
    {
        "name": "robot-2",
        "addr": "127.0.0.1:7947",
        "state": "suspect",
        "incarnation": 2,
        "metrics": None,
        "links": {},
    },
    {
        "name": "robot-3",
        "addr": "127.0.0.1:7948",
        "state": "dead",
        "incarnation": 1,
        "metrics": {"mem_free": 512, "pos": [3, 4.25]},
        "links": {},
    },
    {"name": "robot-4", "addr": "127.0.0.1:7949", "state": "left", "incarnation": 5},
]

PLAIN = """\
NAME     ADDR            STATE    INC  CPU  MEM-FREE  BATTERY  RSSI      POS      LINKS
robot-1  127.0.0.1:7946  alive    0    12%  3.2GB     87%      -47.0dBm  0.0,0.0  typical 0.4ms/0.1ms/0% of 2; robot-3 12ms/2.0ms/25%
robot-2  127.0.0.1:7947  suspect  2    -    -         -        -         -        -
robot-3  127.0.0.1:7948  dead     1    -    512B      -        -         3.0,4.2  -
robot-4  127.0.0.1:7949  left     5    -    -         -        -         -        -"""  # noqa: E501


def test_members_table_plain() -> None:
    assert format_members(MEMBERS) == PLAIN


def test_members_table_coloured_states_keep_alignment() -> None:
    coloured = format_members(MEMBERS, color=True)
    lines = coloured.splitlines()
    assert "\x1b[32malive\x1b[0m    0" in lines[1]
    assert "\x1b[33msuspect\x1b[0m  2" in lines[2]
    assert "\x1b[31mdead\x1b[0m     1" in lines[3]
    assert "\x1b[90mleft\x1b[0m     5" in lines[4]
    # Without the escape codes it is exactly the plain table.
    assert (
        coloured.replace("\x1b[32m", "")
        .replace("\x1b[33m", "")
        .replace("\x1b[31m", "")
        .replace("\x1b[90m", "")
        .replace("\x1b[0m", "")
        == PLAIN
    )


def test_empty_members_table_is_the_header() -> None:
    assert format_members([]) == "NAME  ADDR  STATE  INC  CPU  MEM-FREE  BATTERY  RSSI  POS  LINKS"


@pytest.mark.parametrize(
    ("is_tty", "env", "expected"),
    [
        (True, {}, True),
        (False, {}, False),
        (True, {"NO_COLOR": "1"}, False),
        (True, {"NO_COLOR": ""}, True),
        (True, {"TERM": "dumb"}, False),
    ],
)
def test_want_color(is_tty: bool, env: dict[str, str], expected: bool) -> None:
    assert want_color(is_tty, env) is expected


@pytest.mark.parametrize(
    ("value", "text"),
    [
        (0, "0B"),
        (999, "999B"),
        (1000, "1.0KB"),
        (3_200_000_000, "3.2GB"),
        (4e9, "4.0GB"),
        (2.5e15, "2500.0TB"),
        (None, "-"),
        (True, "-"),
    ],
)
def test_human_bytes(value: object, text: str) -> None:
    assert human_bytes(value) == text


def test_small_unit_helpers() -> None:
    assert human_dbm(-47) == "-47.0dBm"
    assert human_dbm("x") == "-"
    assert human_ms(0.42) == "0.4ms"
    assert human_ms(123.4) == "123ms"
    assert human_seconds(3.21) == "3.2s"
    assert human_seconds(75) == "1m15s"
    assert human_seconds(7300) == "2h01m"
    assert format_link("robot-2", {"rtt_ms": 0.4, "jitter_ms": 0.1, "loss": 0.0}) == (
        "robot-2 0.4ms/0.1ms/0%"
    )
    assert format_link("robot-9", {}) == "robot-9 -/-/-"


def test_render_table_ignores_ansi_in_widths() -> None:
    table = render_table(["A", "B"], [["\x1b[32mxx\x1b[0m", "1"], ["yyy", "2"]])
    assert table.splitlines()[1] == "\x1b[32mxx\x1b[0m   1"
    assert visible_len(table.splitlines()[1]) == len(table.splitlines()[2])


def test_agent_info_snapshot() -> None:
    agent = {
        "name": "robot-1",
        "addr": "127.0.0.1:7946",
        "api": "http://127.0.0.1:8080",
        "version": "0.1.0",
        "uptime_s": 75.0,
        "insecure": True,
        "preset": "lan",
        "launchers": {"offered": ["python", "exec"], "not_offered": {"ros2": "not installed"}},
        "health_score": 0,
        "messages": {
            "in": 10,
            "out": 11,
            "bytes_in": 1500,
            "bytes_out": 2500,
            "bytes_in_per_s": 150.0,
            "bytes_out_per_s": 250.0,
        },
        "rejected": {"replay": 1, "bad_mac": 2},
        "members": {"alive": 3, "suspect": 1, "dead": 0, "left": 0},
    }
    assert format_agent(agent) == (
        "name:         robot-1\n"
        "version:      0.1.0\n"
        "gossip:       127.0.0.1:7946\n"
        "api:          http://127.0.0.1:8080\n"
        "uptime:       1m15s\n"
        "preset:       lan\n"
        "security:     INSECURE (no cluster key)\n"
        "launchers:    python, exec; not ros2: not installed\n"
        "health score: 0\n"
        "members:      alive 3, suspect 1, dead 0, left 0\n"
        "messages:     10 in, 11 out (1.5KB in, 2.5KB out; 150B/s in, 250B/s out)\n"
        "rejected:     bad_mac=2, replay=1"
    )


def test_event_lines() -> None:
    event = {
        "id": 7,
        "ts": 1700000000.125,
        "kind": "member.suspect",
        "robot": "robot-2",
        "detail": {"by": "robot-3"},
    }
    assert format_event(event, tz=UTC) == (
        '    7 22:13:20.125 member.suspect  robot-2   {"by": "robot-3"}'
    )
    assert format_event({**event, "detail": {}}, tz=UTC) == (
        "    7 22:13:20.125 member.suspect  robot-2"
    )
    coloured = format_event(event, tz=UTC, color=True)
    assert "\x1b[33mmember.suspect \x1b[0m" in coloured


def test_metrics_line() -> None:
    metrics = {"cpu_pct": 0.7, "mem_free": 3.9e9, "mem_total": 4e9, "battery_pct": 30.0}
    assert format_metrics({**metrics, "rssi_dbm": -55.34, "pos": [0, 0]}) == (
        "cpu 1%, mem-free 3.9GB/4.0GB, battery 30%, rssi -55.3dBm, pos 0.0,0.0"
    )
