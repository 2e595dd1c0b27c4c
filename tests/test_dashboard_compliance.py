"""The dashboard's Compliance table in a real headless Chromium against real agents: a
component's own battery threshold, its robot's battery dropped below it live (a virtual robot's
`POST /v1/robot`), the row turning from ok to violated with its value and bound, as the status
and the event log say."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from sdrpeer.dashboard.chromium import chromium_page
from tests.browser import chromium_or_fail
from tests.realnet import RealCluster, http
from tests.test_recovery_e2e import deploy, status

pytestmark = pytest.mark.realnet

SYSTEM = """\
name: comply-page
components:
  - name: Pub
    target: tests.components_fixture:Counter
    params: {rate: 5}
    constraints: {battery_above: 50%}
  - name: Rec
    target: tests.components_fixture:Recorder
connections:
  - {from: Pub.out, to: Rec.inp}
compliance: {for: 1s}
recovery:
  rules:
    - {cause: component_error, actions: [restart]}
"""
ROW = '#compliance tr[data-component="Pub"][data-constraint="battery"]'


def battery_row(doc: dict[str, Any]) -> dict[str, Any] | None:
    return next(
        (r for r in doc.get("compliance", []) if r["constraint"] == "battery"),
        None,
    )


def test_the_compliance_table_shows_a_violation(cluster: RealCluster, tmp_path: Path) -> None:
    executable = chromium_or_fail()
    agents = cluster.start_many(2)
    one = agents[0]
    path = tmp_path / "comply.yaml"
    path.write_text(SYSTEM)
    doc = deploy(cluster, one, path)
    robot = next(c["robot"] for c in doc["components"] if c["component"] == "Pub")
    host = next(a for a in agents if a.name == robot)
    row = cluster.wait_until(
        lambda: battery_row(status(one)), lambda r: r is not None, "Pub's battery judged"
    )
    assert row is not None
    assert (row["value"], row["bound"], row["state"]) == (100.0, 50.0, "ok")
    with chromium_page(executable) as page:
        page.goto(one.api + "/")
        page.wait_for_selector(f'{ROW}[data-state="ok"]')
        code, body = http("POST", host.api + "/v1/robot", {"battery": 30}, host.token)
        assert code == 200, body
        page.wait_for_selector(f'{ROW}[data-state="violated"]', timeout=20_000)
        cells = page.eval_on_selector(f"{ROW} ", "r => [...r.cells].map(c => c.textContent)")
        assert cells[:4] == ["Pub", "I", "battery", robot]
        assert cells[4:7] == ["30.0 %", "above 50.0 %", "violated"]
        assert page.errors == []
    doc = status(one)
    assert next(c for c in doc["components"] if c["component"] == "Pub")["compliance"] == (
        "violated"
    )
    violated = [e for e in one.events() if e["kind"] == "compliance.violated"]
    assert violated
    assert violated[0]["detail"]["value"] == 30.0
