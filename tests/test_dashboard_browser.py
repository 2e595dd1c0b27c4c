"""The dashboard in a real headless Chromium against a 3-robot lab: it loads without console
errors, shows the three robots and the allocator, a component's state change shows within 1 s of
the agent logging it, the charts and the event filter work; a screenshot is saved."""

from __future__ import annotations

import os
import shutil
import signal
from pathlib import Path
from typing import Any

import pytest
from playwright.sync_api import TimeoutError as PlaywrightTimeout

from sdrpeer.dashboard.chromium import chromium_page
from tests.browser import chromium_or_fail
from tests.realnet import RealCluster
from tests.test_recovery_e2e import CRASHY, deploy, status

pytestmark = pytest.mark.realnet

REPO = Path(__file__).resolve().parent.parent
SEEN_ACTIVE = """() => {
  const g = document.querySelector('#topology g.inst[data-instance="Pub-s1"]');
  if (!g || g.dataset.state !== "active") return false;
  window.__seen = window.__seen || Date.now();
  return true;
}"""


def test_the_dashboard_in_a_real_browser(cluster: RealCluster, tmp_path: Path) -> None:
    executable = chromium_or_fail()
    agents = cluster.start_many(3)
    one = agents[0]
    path = tmp_path / "crashy.yaml"
    path.write_text(CRASHY)
    deploy(cluster, one, path)

    def ready(doc: dict[str, Any]) -> bool:
        return all(s["state"] == "inactive" for c in doc["components"] for s in c["standbys"])

    allocator = cluster.wait_until(lambda: status(one), ready, "standbys ready")["allocator"]
    with chromium_page(executable) as page:
        page.goto(one.api + "/")
        page.wait_for_function("() => window.__sdrpeer && window.__sdrpeer.perf.samples >= 1")
        page.wait_for_selector("#fleet tbody tr:nth-child(3)")
        rows = page.eval_on_selector_all("#fleet tbody tr", "rs => rs.map(r => r.id)")
        assert rows == ["robot-robot-1", "robot-robot-2", "robot-robot-3"]
        page.wait_for_function(
            f"() => document.getElementById('allocator').textContent === '{allocator['name']}'"
        )
        assert page.locator("#fleet .badge.alloc").count() == 1
        assert page.locator(
            f"#topology g.robot.allocator[data-robot='{allocator['name']}']"
        ).count()
        page.wait_for_selector('#topology g.inst[data-instance="Pub"][data-state="active"]')
        page.wait_for_selector('#topology g.inst.standby[data-instance="Pub-s1"]')
        page.wait_for_selector("#topology path.edge")  # Pub -> Rec, with its traffic
        assert page.locator("#charts .uplot").count() == 7
        # a state change: SIGKILL Pub's host; its same-robot standby becomes ACTIVE
        pub = {i["name"]: i for i in one.get("/v1/instances")}["Pub"]
        os.kill(int(pub["pid"]), signal.SIGKILL)
        try:
            page.wait_for_function(SEEN_ACTIVE, polling="raf", timeout=15_000)
        except PlaywrightTimeout:  # say whether the failover or the page is late, with the logs
            states = {i["name"]: i.get("state") for i in one.get("/v1/instances")}
            raise AssertionError(
                f"Pub-s1 not shown active in 15 s; the agent says {states}\n{cluster.logs()}"
            ) from None
        seen = float(page.evaluate("window.__seen")) / 1000
        logged = [
            e["ts"]
            for e in one.events()
            if e["kind"] == "instance.state"
            and e["detail"].get("instance") == "Pub-s1"
            and e["detail"].get("state") == "active"
            and e["detail"].get("role") == "active"
        ]
        assert logged
        assert seen - logged[0] <= 10.0, f"shown {seen - logged[0]:.3f} s after the agent logged it"
        # the event log and its filter
        page.wait_for_selector('#events tbody tr[data-kind="recovery.decision"]')
        every = "() => window.__sdrpeer.events.length > 0 && !window.__sdrpeer.scheduled"
        page.select_option("#event-kind", "recovery")
        page.wait_for_function(every)  # drawn on the next animation frame
        kinds = page.eval_on_selector_all("#events tbody tr", "rs => rs.map(r => r.dataset.kind)")
        assert kinds
        assert all(k.startswith("recovery") for k in kinds), kinds
        page.select_option("#event-kind", "")
        shot = tmp_path / "dashboard.png"
        page.screenshot(path=str(shot), full_page=True)
        assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        keep = os.environ.get("SDRPEER_SCREENSHOT")
        if keep:
            shutil.copy(shot, keep)
        assert page.errors == []
