"""The dashboard in a real headless Chromium against a 3-robot lab with a robot death (one lab,
every item of issue 18's point 8 but the compliance view):

- the page loads without console errors and shows the robots, the allocator, the charts, the
  event log and its filter;
- the topology of eleven connections is readable: connections between the same two instances
  are one bundle, no text in the drawing overlaps another, and hovering a bundle (or a row of the
  connections table) shows its connections' traffic;
- a connection losing frames (a 400 Hz producer into a 20 Hz consumer) is a warning;
- the robot hosting Fan's active is SIGKILLed: it turns grey with "dead since" and stays, after
  gossip has reaped it, in the table and in the topology;
- Fan's promoted standby keeps its name and says "active (was standby)";
- Fan asks for two standbys on other robots; with two robots left it has one: a warning;
- every component's timeline goes through the failover with no gap, ending ACTIVE;
- `/?snapshot=1` is screenshotted by the `chromium` command line with `--virtual-time-budget`
  (the live stream used to keep the page loading for ever).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import time
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.dashboard.chromium import FLAGS, chromium_page
from tests.browser import chromium_or_fail
from tests.realnet import Agent, RealCluster, http
from tests.test_recovery_e2e import status

pytestmark = pytest.mark.realnet

PORTS = "abcdef"
SYSTEM = (
    """\
name: dash
components:
  - name: Fan
    target: tests.components_fan:Fan
    params: {rate: 10}
    standby: {other_robots: 2, mode: hot}
  - name: Sink
    target: tests.components_fan:Sink
  - name: Pub
    target: tests.components_fixture:Counter
    params: {rate: 400}
  - name: Lag
    target: tests.components_fixture:Laggard
    params: {rate: 20}
connections:
  - {from: Pub.out, to: Lag.inp}
"""
    + "".join(f"  - {{from: Fan.{p}, to: Sink.{p}}}\n" for p in PORTS)
    + "".join(f"  - {{from: Fan.{PORTS[i]}, to: Sink.{PORTS[i + 1]}}}\n" for i in range(4))
)
"""Eleven connections: Pub -> Lag (losing frames), ten from Fan to Sink (one bundle)."""

OVERLAPS = """() => {
  const boxes = [...document.querySelectorAll('#topology text')].map((t) => {
    const b = t.getBBox();
    return [t.textContent, b.x, b.y, b.x + b.width, b.y + b.height];
  });
  const out = [];
  for (let i = 0; i < boxes.length; i++) for (let j = i + 1; j < boxes.length; j++) {
    const [p, a] = [boxes[i], boxes[j]];
    if (p[1] < a[3] && a[1] < p[3] && p[2] < a[4] && a[2] < p[4]) out.push([p[0], a[0]]);
  }
  return [boxes.length, out];
}"""
WATCH_PROMOTED = """() => {
  const look = () => {
    const g = document.querySelector('#topology g.inst.promoted[data-state="active"]');
    if (g) window.__seen = [g.dataset.instance, Date.now()];
    else requestAnimationFrame(look);
  };
  look();
}"""
"""Note when a promoted standby is first drawn ACTIVE (every animation frame until it is)."""
WARNING = "#warnings li[data-kind='{}'][data-subject='{}']"


def ready(doc: dict[str, Any]) -> bool:
    """Every component ACTIVE, Fan's two standbys INACTIVE."""
    comps = doc["components"]
    fan = [c for c in comps if c["component"] == "Fan"]
    return (
        bool(comps)
        and all(c["state"] == "active" for c in comps)
        and bool(fan)
        and len(fan[0]["standbys"]) == 2
        and all(s["state"] == "inactive" for s in fan[0]["standbys"])
    )


def recovered(victim: str) -> Any:
    def ok(doc: dict[str, Any]) -> bool:
        comps = doc["components"]
        return bool(comps) and all(c["state"] == "active" and c["robot"] != victim for c in comps)

    return ok


def deploy_system(cluster: RealCluster, entry: Agent, path: Path) -> None:
    """POST the system to the allocator through `entry` (six host processes start after it)."""
    cluster.wait_until(lambda: status(entry), lambda d: d["allocator"]["name"], "an allocator")
    from sdrpeer.system.loader import load_system  # noqa: PLC0415 - yaml and plugins

    doc = {"system": load_system(path).to_json()}
    code, body = cluster.wait_until(  # 503: a robot's record has not reached the allocator yet
        lambda: http("POST", entry.api + "/v1/deploy", doc, entry.token),
        lambda answer: answer[0] != 503,
        "the deploy answered",
    )
    assert code == 200, body


def reaped(agent: Agent, name: str) -> bool:
    return any(e["kind"] == "member.reaped" and e["robot"] == name for e in agent.events())


def chromium_cli(executable: str, url: str, *args: str) -> subprocess.CompletedProcess[bytes]:
    """The `chromium` command line, headless, with a virtual time budget (no Playwright)."""
    return subprocess.run(
        [executable, *FLAGS, "--window-size=1400,2400", "--virtual-time-budget=8000", *args, url],
        capture_output=True,
        timeout=120,
        check=False,
    )


def test_the_dashboard_through_a_robot_death(cluster: RealCluster, tmp_path: Path) -> None:
    executable = chromium_or_fail()
    agents = cluster.start_many(3)
    path = tmp_path / "dash.yaml"
    path.write_text(SYSTEM)
    deploy_system(cluster, agents[0], path)
    doc = cluster.wait_until(lambda: status(agents[0]), ready, "all ACTIVE, standbys ready", 90)
    assert len(doc["connections"]) == 11
    victim_name = next(c["robot"] for c in doc["components"] if c["component"] == "Fan")
    victim = next(a for a in agents if a.name == victim_name)
    viewer = next(a for a in agents if a is not victim)
    with chromium_page(executable, height=1400) as page:
        page.set_default_timeout(60_000)  # a loaded 2-core machine
        page.goto(viewer.api + "/")
        page.wait_for_function("() => window.__sdrpeer && window.__sdrpeer.perf.samples >= 1")
        page.wait_for_selector("#fleet tbody tr:nth-child(3)")
        rows = page.eval_on_selector_all("#fleet tbody tr", "rs => rs.map(r => r.id)")
        assert rows == ["robot-robot-1", "robot-robot-2", "robot-robot-3"]
        allocator = status(viewer)["allocator"]["name"]
        page.wait_for_function(
            f"() => document.getElementById('allocator').textContent === '{allocator}'"
        )
        assert page.locator("#fleet .badge.alloc").count() == 1
        assert page.locator("#charts .uplot").count() == 7

        # the topology: eleven connections, two bundles, no text over another, labels on hover
        page.wait_for_selector("#connections tbody tr:nth-child(11)")
        page.wait_for_selector("#topology path.edge[data-count='10']")
        assert page.locator("#topology path.edge").count() == 2
        count, overlaps = page.evaluate(OVERLAPS)
        assert count >= 3 + 6  # robot names and instances
        assert overlaps == []
        assert page.locator("#topology text.edge-label").count() == 0  # no labels drawn
        page.hover("#connections tbody tr:nth-child(2)")
        page.wait_for_selector("#edge-tip:not([hidden]) div.this")
        assert page.inner_text("#edge-tip div.this").startswith("Fan.a → Sink.a ·")
        assert page.locator("#edge-tip div").count() == 10  # the whole bundle, one per line
        page.mouse.move(1, 1)  # off the table (onto the header): the tip goes
        page.wait_for_selector("#edge-tip", state="hidden")
        group = page.get_attribute("#topology path.edge[data-count='10']", "data-group")
        page.dispatch_event(f"#topology path.edge-hit[data-group='{group}']", "mouseover")
        page.wait_for_selector("#edge-tip:not([hidden])")
        assert page.locator("#edge-tip div").count() == 10

        # a connection losing frames is a warning, and its edge and row are red
        page.wait_for_selector(WARNING.format("dropping_frames", "Pub.out → Lag.inp"))
        page.wait_for_selector("#connections tr.lossy")

        # the death
        page.evaluate(WATCH_PROMOTED)
        killed_at = time.time()
        cluster.kill(victim)
        page.wait_for_selector(f"#fleet tr#robot-{victim_name}.gone[data-state='dead']")
        assert "dead since" in page.inner_text(f"#fleet tr#robot-{victim_name}")
        doc = cluster.wait_until(lambda: status(viewer), recovered(victim_name), "recovery", 60)
        fan = next(c for c in doc["components"] if c["component"] == "Fan")
        promoted = fan["instance"]
        assert promoted.startswith("Fan-s")  # a standby took over and kept its name
        inst = f"#topology g.inst.promoted[data-instance='{promoted}'][data-state='active']"
        page.wait_for_selector(inst)
        assert page.get_attribute(inst, "data-role") == "active (was standby)"
        assert "active (was standby)" in (page.text_content(inst) or "")
        host = next(a for a in agents if a.name == fan["robot"])
        logged = [
            e["ts"]
            for e in host.events()
            if e["kind"] == "instance.state"
            and e["detail"].get("instance") == promoted
            and e["detail"].get("state") == "active"
        ]
        assert logged
        shown, seen_ms = page.evaluate("window.__seen")
        assert shown == promoted
        assert seen_ms / 1000 - logged[0] <= 10.0, "shown late after its robot logged it"
        page.wait_for_selector(WARNING.format("no_standby", "Fan"))
        assert "1 of 2 standbys" in page.inner_text(WARNING.format("no_standby", "Fan"))

        # reaped by gossip, kept on the page
        cluster.wait_until(lambda: reaped(viewer, victim_name), bool, "the dead robot reaped", 60)
        page.wait_for_selector(f"#fleet tr#robot-{victim_name}[data-reaped='1']")
        assert page.locator(f"#topology g.robot.dead[data-robot='{victim_name}']").count() == 1
        since = page.text_content(f"#topology g.robot[data-robot='{victim_name}'] text.since")
        assert (since or "").startswith("dead since ")
        assert page.evaluate(OVERLAPS)[1] == []  # with the dead robot's second line too

        # every timeline through the failover: no gap, ACTIVE at the end
        page.wait_for_function(
            "(names) => names.every((c) => { const t = window.__sdrpeer.timeline(c);"
            " return t.length && t[t.length - 1][2] === 'active'; })",
            arg=[c["component"] for c in doc["components"]],
        )
        for comp in doc["components"]:
            spans = page.evaluate("(c) => window.__sdrpeer.timeline(c)", comp["component"])
            states = [s[2] for s in spans]
            assert "gone" not in states, (comp["component"], spans)
            assert spans[0][0] < killed_at, (comp["component"], spans)  # drawn from before it
            assert spans[-1][3] == comp["instance"]
        fan_spans = page.evaluate("() => window.__sdrpeer.timeline('Fan')")
        assert (fan_spans[0][3], fan_spans[0][4]) == ("Fan", False)
        assert (fan_spans[-1][3], fan_spans[-1][4]) == (promoted, True)  # was standby

        # the event log and its filter
        page.wait_for_selector('#events tbody tr[data-kind="member.dead"]')
        page.select_option("#event-kind", "member")
        page.wait_for_function(
            "() => window.__sdrpeer.events.length > 0 && !window.__sdrpeer.scheduled"
        )
        kinds = page.eval_on_selector_all("#events tbody tr", "rs => rs.map(r => r.dataset.kind)")
        assert kinds
        assert all(k.startswith("member") for k in kinds), kinds
        page.select_option("#event-kind", "")
        page.dispatch_event("#topology", "mouseleave")  # no tooltip on the picture
        shot = tmp_path / "dashboard.png"
        page.screenshot(path=str(shot), full_page=True)
        assert shot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        keep = os.environ.get("SDRPEER_SCREENSHOT")
        if keep:
            shutil.copy(shot, keep)
        assert page.errors == []

    # a headless screenshot of the snapshot mode ends (the live page never would)
    dom = chromium_cli(executable, viewer.api + "/?snapshot=1", "--dump-dom")
    assert dom.returncode == 0, dom.stderr.decode(errors="replace")[-2000:]
    html = dom.stdout.decode()
    assert 'data-snapshot="ready"' in html
    assert f'id="robot-{victim_name}"' in html
    assert "active (was standby)" in html
    png = tmp_path / "snapshot.png"
    shot_run = chromium_cli(executable, viewer.api + "/?snapshot=1", f"--screenshot={png}")
    assert shot_run.returncode == 0, shot_run.stderr.decode(errors="replace")[-2000:]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
