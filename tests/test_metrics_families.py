"""Prometheus families of an agent that hosts instances and deploys: instances (every robot's
gossiped states, this robot's restarts, CPU, RSS and port traffic), election, allocator,
recovery, state handoff and dashboard figures: each present, with its type and values."""

from __future__ import annotations

from typing import Any

from aiohttp.test_utils import TestClient, TestServer
from prometheus_client.parser import text_string_to_metric_families

from sdrpeer.api.app import build_app
from tests.test_api import EXPECTED_FAMILIES, FakeView

GOSSIPED = [
    {
        "name": "Cam",
        "component": "CameraRTC",
        "state": "active",
        "role": "active",
        "out_bps": 19400,
        "out_lost": 12,
    },
    {"name": "Cam-s1", "component": "CameraRTC", "state": "inactive", "role": "standby"},
]
LOCAL = [
    {
        "name": "Cam",
        "restarts": 2,
        "cpu_pct": 12.5,
        "rss": 25_000_000,
        "ports": {
            "image": {
                "frames_out": 10,
                "bytes_out": 2000,
                "frames_in": 0,
                "bytes_in": 0,
                "dropped": 1,
                "lost": 0,
                "refused": 0,
            },
            "trigger": {
                "frames_in": 3,
                "bytes_in": 30,
                "frames_out": 0,
                "bytes_out": 0,
                "dropped": 0,
                "lost": 2,
                "refused": 1,
            },
        },
    }
]
MORE = {
    "sdrpeer_instance_restarts": "counter",
    "sdrpeer_instance_cpu_ratio": "gauge",
    "sdrpeer_instance_memory_rss_bytes": "gauge",
    "sdrpeer_port_frames": "counter",
    "sdrpeer_port_bytes": "counter",
    "sdrpeer_port_dropped": "counter",
    "sdrpeer_port_lost": "counter",
    "sdrpeer_port_refused": "counter",
    "sdrpeer_port_replayed": "counter",
    "sdrpeer_port_duplicates": "counter",
    "sdrpeer_election_epoch": "gauge",
    "sdrpeer_allocator": "gauge",
    "sdrpeer_is_allocator": "gauge",
    "sdrpeer_recovery_actions": "counter",
    "sdrpeer_recovery_moves": "counter",
    "sdrpeer_state_handoffs": "counter",
    "sdrpeer_events": "counter",
    "sdrpeer_dashboard_streams": "gauge",
}


class Instances:
    def status(self) -> list[dict[str, Any]]:
        return LOCAL


class DeployingView(FakeView):
    instances = Instances()

    def members_view(self) -> list[dict[str, Any]]:
        members = super().members_view()
        members[0]["instances"] = GOSSIPED
        return members

    def deploy_view(self) -> dict[str, Any]:
        return {
            "election": {"epoch": 4, "leader": "robot-1"},
            "recovery_actions": {"restart": 1, "standby_other_robot": 2},
            "recovery_moves": {"CameraRTC": 1},
            "handoff": {"sync_sent": 7, "final_restored": 1},
            "events": {"trap": 3},
            "dashboard_streams": 1,
        }


async def test_every_family_with_its_type_and_values() -> None:
    async with TestClient(TestServer(build_app(DeployingView(), token="t"))) as client:
        text = await (await client.get("/metrics")).text()
    families = {f.name: f for f in text_string_to_metric_families(text)}
    assert {n: f.type for n, f in families.items()} == {**EXPECTED_FAMILIES, **MORE}

    def value(family: str, **labels: str) -> float:
        (match,) = [
            s.value
            for s in families[family].samples
            if all(s.labels.get(k) == v for k, v in labels.items())
            and s.name.endswith("_total" if families[family].type == "counter" else "")
        ]
        return float(match)

    assert value("sdrpeer_instance_state", instance="Cam", state="active") == 1.0
    assert value("sdrpeer_instance_state", instance="Cam", state="error") == 0.0
    assert value("sdrpeer_instance_state", instance="Cam-s1", state="inactive", role="standby") == 1
    assert value("sdrpeer_instance_sent_bytes_per_second", instance="Cam") == 19400.0
    assert value("sdrpeer_instance_lost_frames_per_second", instance="Cam") == 12.0
    assert value("sdrpeer_instance_restarts", instance="Cam") == 2.0
    assert value("sdrpeer_instance_cpu_ratio", instance="Cam") == 0.125
    assert value("sdrpeer_port_bytes", port="image", direction="out") == 2000.0
    assert value("sdrpeer_port_frames", port="trigger", direction="in") == 3.0
    assert value("sdrpeer_port_lost", port="trigger") == 2.0
    assert value("sdrpeer_election_epoch") == 4.0
    assert value("sdrpeer_allocator", robot="robot-1") == 1.0
    assert value("sdrpeer_is_allocator") == 1.0
    assert value("sdrpeer_recovery_actions", action="standby_other_robot") == 2.0
    assert value("sdrpeer_state_handoffs", what="sync_sent") == 7.0
    assert value("sdrpeer_dashboard_streams") == 1.0
