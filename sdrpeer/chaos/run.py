"""`sdrpeer lab chaos`: a seeded chaos soak on a real lab, with its invariants checked all along.

How it works: a lab of `robots` agents starts (each robot in its own network namespace when this
is root with ip, iptables and tc, so partitions and packet loss are real; else on loopback,
without those two faults). A system of `components` components is deployed — camera and
anomaly-detector pairs, each with a hot standby on another robot, and Table III's rules for
errors, lost signal, low battery and packet loss, spread by the `objective` strategy (first_fit
would put every active on robot-1 and every standby on robot-2). Then, for `minutes`, the faults
of `schedule.schedule(seed, ...)` are carried out (SIGKILL of a component host — on the next
robot that runs one when the drawn robot runs none — or of an agent, which is restarted later;
RSSI or battery pushed past the rules through the robot's API; a partition; packet loss, which
spares the runner's own calls) while the fleet is looked at four times a second: every robot's
own list of instances, its plan key and its agent's RSS go to `judge.Judge`. When the last fault
has ended the soak waits (at most `settle_s`) for the fleet to be whole again, checks the final
plan, stops the lab and returns the judge's report plus what was done.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import signal
import tempfile
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import psutil

from sdrpeer.chaos.elections import elections
from sdrpeer.chaos.judge import Judge, Look
from sdrpeer.chaos.schedule import Fault, schedule
from sdrpeer.client import AgentClient, post_when_elected, wait_for
from sdrpeer.errors import ApiError, SdrpeerError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.netlab import net
from sdrpeer.netlab.plan import PART_CHAIN
from sdrpeer.record.robot import state_to_wire
from sdrpeer.system.loader import parse_system
from sdrpeer.vocabulary import InstanceRole, LifecycleState

LOOK_EVERY = 0.25
"""Seconds between two looks at the fleet (each asks every robot at once, in parallel)."""


@dataclass(frozen=True, slots=True)
class ChaosOptions:
    """What `sdrpeer lab chaos` was asked for."""

    robots: int = 10
    components: int = 20
    minutes: float = 1.0
    seed: int = 1
    netns: bool | None = None
    """None: the namespace lab when this is root with the tools, else loopback."""
    settle_s: float = 30.0
    lab_dir: Path | None = None


def chaos_system(components: int) -> dict[str, Any]:
    """Camera -> AnomalyDetection pairs (small, real pixel work), hot standbys elsewhere."""
    lines = ["name: chaos", "allocation: {strategy: objective}", "components:"]
    conns = ["connections:"]
    for k in range((components + 1) // 2):
        lines += [
            f"  - name: Cam{k}",
            "    target: components.camera:Camera",
            "    params: {reserve_mb: 0, rate: 2, width: 32, height: 24}",
            "    requires: {cpu: 2%, memory: 30MB}",
            "    standby: {other_robots: 1, mode: hot}",
        ]
        if 2 * k + 1 < components:
            lines += [
                f"  - name: Det{k}",
                "    target: components.anomaly_detection:AnomalyDetection",
                "    params: {reserve_mb: 0}",
                "    requires: {cpu: 2%, memory: 30MB}",
                "    standby: {other_robots: 1, mode: hot}",
            ]
            conns.append(f"  - {{from: Cam{k}.image, to: Det{k}.image, policy: {{push: new}}}}")
    rules = [
        "recovery:",
        "  min_dwell: 5s",
        "  rules:",
        "    - {cause: component_error,"
        " actions: [restart, standby_other_robot, launch_other_robot]}",
        "    - {cause: communication_failure, when: rssi <= -52.5dBm, for: 2s, clear: -50dBm,"
        " actions: [standby_other_robot, launch_other_robot]}",
        "    - {cause: communication_failure, when: loss >= 30%, for: 3s, clear: 20%,"
        " actions: [standby_other_robot, launch_other_robot]}",
        "    - {cause: low_battery, when: battery <= 15%, for: 2s, clear: 20%,"
        " actions: [standby_other_robot, launch_other_robot]}",
    ]
    text = "\n".join([*lines, *(conns if len(conns) > 1 else []), *rules]) + "\n"
    return parse_system(text, "chaos.yaml").to_json()


class Soak:
    """One soak on a started lab."""

    def __init__(self, lab: RunningLab, components: list[str], say: Callable[[str], None]) -> None:
        self.lab = lab
        self.say = say
        self.clients = {
            r.name: AgentClient(str(r.api), r.token, timeout=1.5) for r in lab.lab.robots
        }
        self.judge = Judge(components)
        self.done: list[dict[str, Any]] = []
        self.down: set[str] = set()
        self.partitioned = False
        self.t0 = time.monotonic()
        """Where the soak's clock starts (reset when the faults begin)."""
        self.pool = ThreadPoolExecutor(max_workers=len(self.clients), thread_name_prefix="look")

    # -- faults ----------------------------------------------------------------------------

    def start(self, fault: Fault, t: float) -> None:
        """Carry a fault out (and tell the judge)."""
        robot = fault.robots[0]
        what = ""
        if fault.kind == "kill_host":
            what = self._kill_host(robot, fault.pick)
        elif fault.kind == "kill_agent":
            self._kill_agent(robot)
        elif fault.kind in ("rssi", "battery"):
            value = "-60dBm" if fault.kind == "rssi" else "10%"
            self._set(robot, {fault.kind: value})
        elif fault.kind == "partition":
            plan = self.lab.net
            assert plan is not None
            rest = [n for n in plan.names() if n not in fault.robots]
            net.run(plan.partition([list(fault.robots), rest]))
            self.partitioned = True
        elif fault.kind == "loss":
            assert self.lab.net is not None
            net.run(self.lab.net.loss(robot, fault.amount, spare_host=True))  # looks see all
        if what != "skipped":
            self.judge.fault(
                t, fault.kind, None if fault.until is None else t + fault.until - fault.at
            )
        until = None if fault.until is None else round(t + fault.until - fault.at, 2)
        self.done.append({"t": round(t, 2), "kind": fault.kind, "robots": list(fault.robots),
                          "until": until, "note": what})  # fmt: skip

    def end(self, fault: Fault) -> None:
        """Undo a fault that has an end."""
        robot = fault.robots[0]
        if fault.kind == "kill_agent":
            self.lab.restart(robot)
            self.down.discard(robot)
        elif fault.kind == "rssi":
            self._set(robot, {"rssi": "-45dBm"})
        elif fault.kind == "battery":
            self._set(robot, {"battery": "90%"})
        elif fault.kind == "partition" and self.lab.net is not None:
            plan = self.lab.net
            net.run([plan.in_ns(r, "iptables", "-F", PART_CHAIN) for r in plan.names()])
            self.partitioned = False
            self.judge.healed(time.monotonic() - self.t0)  # once every rule is gone
        elif fault.kind == "loss" and self.lab.net is not None:
            net.run(self.lab.net.loss(robot, 0.0))

    def _kill_host(self, robot: str, pick: int) -> str:
        """SIGKILL an ACTIVE host of `robot`, or, when it runs none (the allocation may gather
        the actives on a few robots), of the next robot in name order that does (every robot
        asked at once: a slow one must not stall the soak's looks); "skipped" when no robot
        runs one, else "" or "on ROBOT"."""
        names = list(self.clients)
        start = names.index(robot)
        order = [n for n in names[start:] + names[:start] if n not in self.down]
        for name, rows in zip(order, self.pool.map(self._instances, order), strict=True):
            pids = [
                r["pid"] for r in rows if r.get("state") == LifecycleState.ACTIVE and r.get("pid")
            ]
            if pids:
                with contextlib.suppress(ProcessLookupError):
                    os.kill(int(pids[pick % len(pids)]), signal.SIGKILL)
                return "" if name == robot else f"on {name}"
        return "skipped"

    def _instances(self, robot: str) -> list[dict[str, Any]]:
        """A robot's own list of instances ([] when it does not answer)."""
        try:
            rows: list[dict[str, Any]] = self.clients[robot].get("/v1/instances")
        except ApiError:
            return []
        return rows

    def _kill_agent(self, robot: str) -> None:
        proc = self.lab.procs[robot]
        with contextlib.suppress(ProcessLookupError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait(10)
        self.down.add(robot)

    def _set(self, robot: str, changes: dict[str, str]) -> None:
        if robot not in self.down:
            with contextlib.suppress(ApiError):
                self.clients[robot].post("/v1/robot", changes)

    # -- looking ---------------------------------------------------------------------------

    def look(self, t: float) -> Look:
        """Every running robot's own word on its instances and plan, and its agent's RSS (all
        robots asked at once: a look is as slow as the slowest robot, not their sum)."""
        actives: dict[str, set[str]] = {}
        plans: dict[str, tuple[int, str, int] | None] = {}
        rss: dict[str, int] = {}
        up = [r for r in self.clients if r not in self.down]
        for robot, answer in zip(up, self.pool.map(self._ask, up), strict=True):
            if answer is None:
                continue
            rows, status = answer
            for row in rows:
                if (
                    row.get("state") == LifecycleState.ACTIVE
                    and row.get("role") == InstanceRole.ACTIVE
                ):
                    actives.setdefault(str(row["component"]), set()).add(robot)
            p = status.get("plan")
            plans[robot] = None if p is None else (p["epoch"], p["allocator"], p["version"])
            with contextlib.suppress(psutil.Error):
                rss[robot] = psutil.Process(self.lab.procs[robot].pid).memory_info().rss
        frozen = {c: frozenset(r) for c, r in actives.items()}
        return Look(t, frozen, plans, rss, self.partitioned)

    def _ask(self, robot: str) -> tuple[list[dict[str, Any]], dict[str, Any]] | None:
        client = self.clients[robot]
        try:
            return client.get("/v1/instances"), client.get("/v1/status")
        except ApiError:
            return None


def run_chaos(opts: ChaosOptions, say: Callable[[str], None] = print) -> dict[str, Any]:
    """Run one soak; its report."""
    netns = opts.netns
    if netns is None:
        try:
            net.require_tools()
            netns = True
        except SdrpeerError:
            netns = False
    with tempfile.TemporaryDirectory() as tmp:
        lab_dir = opts.lab_dir or Path(tmp) / "lab"
        say(f"chaos: {opts.robots} robots ({'namespaces' if netns else 'loopback'}), "
            f"{opts.components} components, {opts.minutes:g} min, seed {opts.seed}")  # fmt: skip
        lab = start_lab(
            UpOptions(opts.robots, lab_dir, preset="lan", netns=netns, timeout=60),
            say=lambda _: None,
        )
        try:
            report = _soak(lab, opts, netns, say)
        finally:
            lab.stop(grace=3)
        report["leaked_processes"] = _reap_leftovers(lab_dir)
        return report


def _reap_leftovers(lab_dir: Path) -> list[str]:
    """Kill (and name) every process still running from the lab after it was stopped: an agent
    or host that outlived `lab.stop` is a leak the soak reports."""
    marker = str(lab_dir)
    found = []
    mine = {os.getpid(), *(p.pid for p in psutil.Process().parents())}  # `timeout ... --keep
    # DIR` around the soak names the lab too: it was killed as a leftover of its own soak
    for proc in psutil.process_iter(["pid", "cmdline"]):
        cmdline = proc.info.get("cmdline") or []
        if proc.pid not in mine and any(marker in part for part in cmdline):
            found.append(f"pid {proc.pid}: {' '.join(cmdline)[:200]}")
            with contextlib.suppress(psutil.Error):
                proc.kill()
    return found


def _soak(
    lab: RunningLab, opts: ChaosOptions, netns: bool, say: Callable[[str], None]
) -> dict[str, Any]:
    system = chaos_system(opts.components)
    components = [c["name"] for c in system["components"]]
    soak = Soak(lab, components, say)
    first = soak.clients["robot-1"]
    post_when_elected(first, "/v1/deploy", {"system": system}, 30.0)

    def ready(doc: dict[str, Any]) -> bool:
        comps = doc.get("components") or []
        return bool(comps) and all(
            c["state"] == state_to_wire(LifecycleState.ACTIVE)
            and all(s["state"] == state_to_wire(LifecycleState.INACTIVE) for s in c["standbys"])
            for c in comps
        )

    wait_for(lambda: first.get("/v1/status"), ready, "the system deployed", 120)
    duration = opts.minutes * 60
    faults = schedule(opts.seed, opts.robots, duration, netns)
    ends = sorted(((f.until, i) for i, f in enumerate(faults) if f.until is not None))
    say(f"deployed; {len(faults)} faults over {duration:g} s")
    t0 = soak.t0 = time.monotonic()
    t0_wall = time.time()
    started = ended = 0
    next_look = 0.0
    while True:
        t = time.monotonic() - t0
        due, started, ended = due_events(faults, ends, started, ended, t)
        for what, i in due:
            if what == "end":
                soak.end(faults[i])
            else:
                soak.start(faults[i], t)
        if started == len(faults) and ended == len(ends) and t >= duration:
            break
        if t >= next_look:
            soak.judge.observe(soak.look(t))
            next_look = t + LOOK_EVERY
            continue  # a look takes time: start what fell due meanwhile first
        time.sleep(0.05)
    t_over = time.monotonic() - t0
    soak.judge.faults_over(t_over)
    deadline = t_over + opts.settle_s
    while time.monotonic() - t0 < deadline:
        if soak.judge.observe(soak.look(time.monotonic() - t0)):
            break
        time.sleep(0.1)
    else:
        soak.judge.never_converged(time.monotonic() - t0)
    placed = _placed(soak)
    logs = _events(soak)
    if opts.lab_dir is not None:
        for robot, events in logs.items():
            (opts.lab_dir / robot).mkdir(parents=True, exist_ok=True)
            (opts.lab_dir / robot / "events.json").write_text(json.dumps(events))
    soak.pool.shutdown()
    soak.judge.final_plan(placed)
    report = soak.judge.report()
    report.update(
        robots=opts.robots,
        components=opts.components,
        minutes=opts.minutes,
        seed=opts.seed,
        network="namespaces" if netns else "loopback",
        t0_wall=round(t0_wall, 3),  # unix time of t = 0: events.json entries map onto t
        faults_done=soak.done,
        elections=elections(logs, soak.done, t0_wall),
    )
    return report


def due_events(
    faults: list[Fault], ends: list[tuple[float, int]], started: int, ended: int, t: float
) -> tuple[list[tuple[str, int]], int, int]:
    """The starts and ends due at `t` ("start"/"end", fault index), in the order they fell due,
    and the new counts: a slow look may leave several due at once, and a robot whose agent is
    killed twice must have been restarted in between (else two agents run for one robot and the
    first outlives the lab)."""
    out: list[tuple[str, int]] = []
    while True:
        next_start = faults[started].at if started < len(faults) else math.inf
        next_end = ends[ended][0] if ended < len(ends) else math.inf
        if min(next_start, next_end) > t:
            return out, started, ended
        if next_end <= next_start:
            out.append(("end", ends[ended][1]))
            ended += 1
        else:
            out.append(("start", started))
            started += 1


def _events(soak: Soak) -> dict[str, list[Any]]:
    """Every running robot's event log (the agents keep them in memory only): for the
    elections' count, and into ROBOT/events.json of a kept lab (`--keep`) to find what happened
    behind a violation."""
    logs: dict[str, list[Any]] = {}
    for robot, client in soak.clients.items():
        if robot in soak.down:
            continue
        events: list[Any] = []
        since = 0
        with contextlib.suppress(ApiError):
            while len(events) < 100_000:
                page = client.get(f"/v1/events?since={since}&limit=1000")
                if not page:
                    break
                events += page
                since = int(page[-1]["id"])
        logs[robot] = events
    return logs


def _placed(soak: Soak) -> dict[str, int]:
    """Component -> active placements in the plan one running robot holds at the end."""
    for robot, client in soak.clients.items():
        if robot in soak.down:
            continue
        try:
            doc = client.get("/v1/status")
        except ApiError:
            continue
        return {c["component"]: 1 if c.get("instance") else 0 for c in doc.get("components") or []}
    return {}


def format_report(r: dict[str, Any]) -> str:
    """The soak's report for a person."""
    rec = r["recovery_s"]
    lines = [
        f"chaos soak: {r['robots']} robots ({r['network']}), {r['components']} components, "
        f"{r['minutes']:g} min, seed {r['seed']}",
        f"faults injected: {r['faults_total']}  "
        + ", ".join(f"{k} {v}" for k, v in r["faults"].items()),
        f"recoveries: {r['recoveries']}  time to whole again: p50 {rec['p50']} s, "
        f"p99 {rec['p99']} s, max {rec['max']} s",
        *(
            f"  {label}: {f['n']}, p50 {f['p50']} s, p99 {f['p99']} s, max {f['max']} s"
            for label, f in (
                ("isolated (no other fault on)", r["recovery_isolated_s"]),
                ("overlapping", r["recovery_overlapping_s"]),
            )
        ),
        "  isolated, by kind: "
        + (", ".join(f"{k} {v}" for k, v in r["recovery_isolated_by_kind"].items()) or "none"),
        f"after the last fault: whole again in {r['converged_after_s']} s (target <= 3 s)",
        f"two actives once the network was whole: {r['double_active_episodes']} episodes, longest "
        f"{r['double_active_max_s']} s seen (window {r['fence_window_s']:g} s; looks every "
        f"{r['look_interval_s']['p50']} s, p99 {r['look_interval_s']['p99']} s)",
        f"agents' RSS: peak {r['agent_rss_peak_mib']} MiB, largest growth "
        f"{r['agent_rss_growth_mib']} MiB",
        _elections_line(r.get("elections")),
        f"violations: {len(r['violations'])} (target 0)",
    ]
    if r.get("leaked_processes"):
        lines.append(f"processes left running after the lab stopped: {r['leaked_processes']}")
    lines += [f"  {v}" for v in r["violations"][:20]]
    return "\n".join(lines)


def _elections_line(e: dict[str, Any] | None) -> str:
    """How many elections, why, and how many of them were churn among living members."""
    if e is None:
        return "elections: not counted"
    why = ", ".join(f"{k} {v}" for k, v in sorted(e["by_reason"].items()))
    return f"elections: {e['total']} ({why}); churn among living members: {e['churn']}"
