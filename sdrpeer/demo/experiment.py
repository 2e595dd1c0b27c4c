"""One run of the paper's experiment (section III) on a local lab, measured.

How it works:
1. robot files from examples/robots (2000MB each: with Table V two 550MB components fit on a
   robot, three do not, so the five split 2 + 2 + 1 as in Fig. 3); the robot chosen to hold the
   allocator first gets the highest election priority; a scenario file drops robot-1's RSSI from
   about -47 to -55 dBm at `drop_at` seconds after its agent started (paper: 107 s);
2. a lab of three real agents (`lan` preset) and a `TimelineRecorder` polling them;
3. the paper's system (examples/paper/system.yaml: five components, `reserve_mb` each, Tables V
   and VI) is deployed through robot-1 (the robot that "first acquires the configuration");
   the clock runs from the deploy request to all five ACTIVE (status polled every 50 ms);
4. robot-1's signal falls; the recovery rule (RSSI <= -52.5 dBm held `sustain` s) fires on the
   allocator, which moves robot-1's components; the clock runs from the fault (the scenario's
   own event on robot-1) to the condition (the allocator's `recovery.condition` event) to every
   component ACTIVE off robot-1;
5. the timeline, Figs. 4-6 and a summary are written to the run's folder.
"""

from __future__ import annotations

import json
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from sdrpeer.client import AgentClient, post_when_elected, wait_for
from sdrpeer.demo.query import Timeline
from sdrpeer.demo.timeline import TimelineRecorder, load_timeline
from sdrpeer.errors import ApiError
from sdrpeer.eventlog import EventKind
from sdrpeer.lab.up import UpOptions, start_lab
from sdrpeer.record.robot import state_to_wire
from sdrpeer.system.loader import parse_system
from sdrpeer.vocabulary import InstanceRole, LifecycleState

REPO = Path(__file__).resolve().parent.parent.parent
RSSI_THRESHOLD = -52.5


@dataclass(frozen=True, slots=True)
class RunOptions:
    """One run of the experiment."""

    out: Path
    allocator_on: str
    """The robot given the highest election priority (it holds the allocator first)."""
    reserve_mb: int = 500
    sustain_s: float = 6.0
    drop_at: float = 45.0
    """Seconds after robot-1's agent starts when its RSSI falls (paper: 107 s)."""
    after_s: float = 8.0
    """How long to keep recording once recovery is done (the figures' tail)."""
    timeout: float = 120.0
    openrtm: bool = False
    """Deploy the RT-Component versions (examples/paper/system-openrtm.yaml, components/openrtm/,
    the `openrtm` launcher allowed on every robot) instead of the SDK components."""

    @property
    def system_file(self) -> Path:
        """The system file this run deploys."""
        name = "system-openrtm.yaml" if self.openrtm else "system.yaml"
        return REPO / "examples/paper" / name


@dataclass(slots=True)
class RunResult:
    """What one run measured (seconds; None when it did not happen)."""

    allocator_first: str | None = None
    allocator_after: str | None = None
    placement: dict[str, str] = field(default_factory=dict)
    placement_after: dict[str, str] = field(default_factory=dict)
    deploy_to_active_s: float | None = None
    fault_to_condition_s: float | None = None
    condition_to_active_s: float | None = None
    fault_to_active_s: float | None = None
    figures: list[str] = field(default_factory=list)


def system_text(reserve_mb: int, sustain_s: float, path: Path | None = None) -> str:
    """examples/paper/system.yaml (or `path`) with its reserve and the RSSI rule's sustain
    changed."""
    text = (path or REPO / "examples/paper/system.yaml").read_text()
    text = text.replace("reserve_mb: 500", f"reserve_mb: {reserve_mb}")
    return text.replace("for: 6s", f"for: {sustain_s:g}s")


def prepare(opts: RunOptions) -> tuple[Path, Path]:
    """Write the run's robot files and scenario; (robot files dir, scenario path)."""
    robots = opts.out / "robots"
    robots.mkdir(parents=True, exist_ok=True)
    for src in sorted((REPO / "examples/robots").glob("robot-*.yaml")):
        lines = [ln for ln in src.read_text().splitlines() if not ln.startswith("priority:")]
        priority = 10 if src.stem == opts.allocator_on else 0
        (robots / src.name).write_text("\n".join([*lines, f"priority: {priority}"]) + "\n")
    scenario = opts.out / "scenario.yaml"
    scenario.write_text(
        "description: robot-1 enters a weak-field area (paper Fig. 4b)\n"
        f"steps:\n  - {{at: {opts.drop_at:g}s, robot: robot-1, set: {{rssi: -55dBm}}}}\n"
    )
    return robots, scenario


def _placed(doc: dict[str, Any]) -> dict[str, str]:
    return {c["component"]: c["robot"] for c in doc.get("components", [])}


def _all_active(off: str | None = None) -> Callable[[dict[str, Any]], bool]:
    def ok(doc: dict[str, Any]) -> bool:
        comps = doc.get("components") or []
        return bool(comps) and all(
            c["state"] == state_to_wire(LifecycleState.ACTIVE)
            and (off is None or c["robot"] != off)
            for c in comps
        )

    return ok


def run(opts: RunOptions, say: Callable[[str], None] = print) -> RunResult:
    """Run the experiment once; everything is written under `opts.out`."""
    robots, scenario = prepare(opts)
    paper = opts.system_file
    system = parse_system(system_text(opts.reserve_mb, opts.sustain_s, paper), str(paper))
    result = RunResult()
    lab_options = UpOptions(
        3,
        opts.out / "lab",
        preset="lan",
        robot_files=robots,
        scenario=scenario,
        timeout=30,
        allow_launchers=("openrtm",) if opts.openrtm else (),
    )
    lab = start_lab(lab_options, say=lambda _: None)
    apis = {r.name: str(r.api) for r in lab.lab.robots}
    clients = {r.name: AgentClient(str(r.api), r.token) for r in lab.lab.robots}
    recorder = TimelineRecorder(apis, opts.out / "timeline.jsonl")
    recorder.start()
    try:
        one, two = clients["robot-1"], clients["robot-2"]
        doc = wait_for(
            lambda: two.get("/v1/status"),
            lambda d: d["allocator"]["name"] == opts.allocator_on,
            f"{opts.allocator_on} elected",
            30,
        )
        result.allocator_first = doc["allocator"]["name"]
        say(
            f"  allocator elected: {result.allocator_first}; deploying {system.name} "
            f"({len(system.components)} components, reserve {opts.reserve_mb} MB each)"
        )
        t0 = time.time()
        recorder.mark("allocation", "deploy")
        post_when_elected(one, "/v1/deploy", {"system": system.to_json()}, 15.0)
        doc = wait_for(lambda: one.get("/v1/status"), _all_active(), "all ACTIVE", opts.timeout)
        result.deploy_to_active_s = round(time.time() - t0, 3)
        result.placement = _placed(doc)
        say(f"  all ACTIVE after {result.deploy_to_active_s:.2f} s: {result.placement}")
        say(f"  waiting for robot-1's signal to fall (scenario: {opts.drop_at:g} s after start)")
        doc = wait_for(
            lambda: two.get("/v1/status"),
            _all_active(off="robot-1"),
            "recovery off robot-1",
            opts.drop_at + opts.sustain_s + opts.timeout,
        )
        t_done = time.time()
        result.placement_after = _placed(doc)
        result.allocator_after = doc["allocator"]["name"]
        _times(result, clients, t_done)
        say(f"  recovered: {result.placement_after}; allocator {result.allocator_after}")
        time.sleep(opts.after_s)
    finally:
        recorder.stop()
        lab.stop(grace=5)
    path = opts.out / "timeline.jsonl"
    marks = recovery_marks(load_timeline(path))
    with path.open("a") as f:
        f.writelines(json.dumps(m) + "\n" for m in marks)
    lines = load_timeline(path)
    from sdrpeer.demo.figures import render_figures  # noqa: PLC0415 - matplotlib: only here

    result.figures = [str(p) for p in render_figures(lines, opts.out)]
    (opts.out / "summary.json").write_text(json.dumps(asdict(result), indent=2))
    return result


def _times(result: RunResult, clients: dict[str, AgentClient], t_done: float) -> None:
    """Fault, condition and recovery times from the agents' own event logs (wall clock)."""
    events = [e for c in clients.values() for e in _events(c)]
    fault = min(
        (e["ts"] for e in events if e["kind"] == "scenario" and e["robot"] == "robot-1"),
        default=None,
    )
    allocator = result.allocator_after
    cond = [
        e["ts"]
        for e in events
        if e["kind"] == EventKind.RECOVERY_CONDITION
        and e["robot"] == allocator
        and (e.get("detail") or {}).get("subject") == "robot-1"
    ]
    t_cond = min(cond, default=None)
    last_active = _last_activation(events, since=t_cond) if t_cond is not None else None
    done = last_active if last_active is not None else t_done
    if fault is not None and t_cond is not None:
        result.fault_to_condition_s = round(t_cond - fault, 3)
    if t_cond is not None:
        result.condition_to_active_s = round(done - t_cond, 3)
    if fault is not None:
        result.fault_to_active_s = round(done - fault, 3)


def _events(client: AgentClient) -> list[dict[str, Any]]:
    try:
        batch: list[dict[str, Any]] = client.get("/v1/events", limit=10000)
    except ApiError:
        return []
    return batch


def _last_activation(events: list[dict[str, Any]], since: float) -> float | None:
    """When the last instance that became ACTIVE (role active) after `since` did so."""
    times = [
        e["ts"]
        for e in events
        if e["kind"] == EventKind.INSTANCE_STATE
        and e["ts"] >= since
        and (e.get("detail") or {}).get("state") == state_to_wire(LifecycleState.ACTIVE)
        and (e.get("detail") or {}).get("role") == InstanceRole.ACTIVE
    ]
    return max(times, default=None)


def recovery_marks(lines: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A recovery mark at every recovery.move event of the timeline (the figures draw marks)."""
    return [
        {"t": line["t"], "kind": "mark", "what": "recovery", "label": "move"}
        for line in lines
        if line.get("kind") == "event" and line.get("event") == EventKind.RECOVERY_MOVE
    ]


def timeline_of(out: Path) -> Timeline:
    """The recorded timeline of a run folder."""
    return Timeline(load_timeline(out / "timeline.jsonl"))
