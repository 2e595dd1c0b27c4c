"""The dashboard's warnings (pure): standbys short of what the system asks for, frames lost."""

from __future__ import annotations

from typing import Any

import pytest

from sdrpeer.dashboard.warnings import Overflows, fleet_warnings


def comp(name: str, wanted: int, *standbys: str) -> dict[str, Any]:
    return {
        "component": name,
        "instance": name,
        "robot": "r1",
        "state": "active",
        "standbys_wanted": wanted,
        "standbys": [
            {"instance": f"{name}-s{k + 1}", "robot": f"r{k + 2}", "state": s}
            for k, s in enumerate(standbys)
        ],
    }


@pytest.mark.parametrize(
    ("component", "text"),
    [
        (comp("A", 0), None),  # asks for none
        (comp("A", 1, "inactive"), None),
        (comp("A", 1, "cold"), None),  # a cold standby is one: it starts when needed
        (comp("A", 1, "pending"), None),  # being started
        (comp("A", 2, "inactive"), "A: 1 of 2 standbys the system asks for; 1 not placed"),
        (comp("A", 1), "A: 0 of 1 standbys the system asks for; 1 not placed"),
        (comp("A", 1, "robot down"), "A: 0 of 1 standbys the system asks for; A-s1 on r2: robot"),
        (comp("A", 2, "error", "lost"), "A: 0 of 2 standbys the system asks for; A-s1 on r2: err"),
        ({"component": "A", "standbys": []}, None),  # an older agent's status: no figure
    ],
)
def test_a_component_short_of_standbys(component: dict[str, Any], text: str | None) -> None:
    warnings = fleet_warnings({"components": [component]})
    if text is None:
        assert warnings == []
    else:
        (w,) = warnings
        assert (w["kind"], w["subject"]) == ("no_standby", "A")
        assert w["text"].startswith(text)


def test_connections_losing_frames_and_overflow_events() -> None:
    status = {
        "connections": [
            {"from": "Pub.out", "to": "Lag.inp", "lost_per_s": 37},
            {"from": "Cam.image", "to": "Det.image", "lost_per_s": 0},
            {"from": "Odo.pose", "to": "Ctl.pose", "lost_per_s": None},
        ]
    }
    seen = Overflows()
    for ts, instance, component in ((10.0, "Pub", "Pub"), (20.0, "Ctl-s1", "Ctl"), (1.0, "X", "X")):
        seen.add(
            {
                "ts": ts,
                "kind": "port.overflow",
                "robot": "r1",
                "detail": {
                    "instance": instance,
                    "component": component,
                    "port": "out",
                    "frames": 5,
                },
            }
        )
    warnings = fleet_warnings(status, seen.recent(65.0))
    assert [(w["kind"], w["subject"]) for w in warnings] == [
        ("dropping_frames", "Pub.out → Lag.inp"),
        ("dropping_frames", "Ctl-s1.out"),  # Pub's event: said once, by its connection; X: old
    ]
    assert warnings[0]["text"] == "Pub.out → Lag.inp: its sender loses 37 frames/s to full buffers"
    assert fleet_warnings(None) == []


def test_overflows_keep_the_newest_per_port_and_are_bounded() -> None:
    seen = Overflows(max_kept=2)
    for ts, port in ((1.0, "a"), (2.0, "b"), (3.0, "a"), (4.0, "c")):
        seen.add({"ts": ts, "detail": {"instance": "I", "port": port}})
    assert [(e["ts"], e["detail"]["port"]) for e in seen.recent(4.0)] == [(3.0, "a"), (4.0, "c")]
