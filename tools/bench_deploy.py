"""Deployment benchmark on real agents: deploy -> all ACTIVE, and allocator death -> new allocator.

Usage: python tools/bench_deploy.py [--json out.json] [--runs 5] [--reserve 0,500] [--kills 3]
                                    [--preset lan]

How it works: a local lab of three real agents (`sdrpeer.lab.up`, robot files with 2000MB of
memory so that Table V — free memory above 500MB after adding a 500MB component — splits the
paper's five components 2 + 2 + 1, as in the paper's Fig. 3). For each `reserve_mb` value the
paper's system (the five components of `components/`, wired as in Fig. 3, `requires: memory:
500MB`) is deployed `--runs` times: the clock starts when `POST /v1/deploy` is sent to robot-2
and stops when robot-2's `GET /v1/status` (polled every 10 ms) shows all five ACTIVE; then the
system is undeployed and the next run waits until every host has exited and every robot's
record shows its memory free again. With `reserve_mb: 500`
each component really allocates and touches 500 MB on activation (the paper: ~16 s on Raspberry
Pi 4s). Election: `--kills` times a fresh lab elects an allocator, the allocator's agent is
SIGKILLed, and the clock stops when every surviving agent names the same new allocator with a
higher epoch (polled every 10 ms; the agents use the `--preset` timers).
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import statistics
import sys
import tempfile
import time
from functools import partial
from pathlib import Path
from typing import Any

from sdrpeer.client import AgentClient, wait_for
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.system.loader import parse_system

TARGET_DEPLOY_S = 1.0
MEM_BACK = 1_750_000_000  # bytes free per 2000MB robot once its hosts are gone
COMPONENTS = {
    "OmnidirectionalCameraRTC": "components.camera:OmnidirectionalCamera",
    "AnomalyDetectionRTC": "components.anomaly_detection:AnomalyDetection",
    "CameraRTC": "components.camera:Camera",
    "REDControllerRTC": "components.red_controller:REDController",
    "PositionEstimationRTC": "components.position_estimation:PositionEstimation",
}
WIRING = """\
connections:
  - {from: OmnidirectionalCameraRTC.image, to: AnomalyDetectionRTC.image, policy: {push: new}}
  - {from: AnomalyDetectionRTC.alarm, to: REDControllerRTC.alarm, policy: {push: new}}
  - {from: REDControllerRTC.odometry, to: PositionEstimationRTC.odometry}
  - {from: PositionEstimationRTC.pose, to: REDControllerRTC.pose, policy: {push: new}}
allocation:
  strategy: first_fit
  constraints: {mem_free_above: 500MB}
"""


def system_text(reserve_mb: int) -> str:
    """The paper's system with every component reserving `reserve_mb`."""
    lines = ["version: 1", f"name: paper-bench-{reserve_mb}", "components:"]
    for name, target in COMPONENTS.items():
        lines += [
            f"  - name: {name}",
            f"    target: {target}",
            f"    params: {{reserve_mb: {reserve_mb}}}",
            "    requires: {cpu: 5%, memory: 500MB}",
        ]
    return "\n".join(lines) + "\n" + WIRING


def robot_files(root: Path) -> Path:
    """robot-1..3.yaml with 2000MB each (Fig. 3's split under Table V)."""
    folder = root / "robots"
    folder.mkdir(parents=True, exist_ok=True)
    for i in (1, 2, 3):
        (folder / f"robot-{i}.yaml").write_text(
            f"name: robot-{i}\nmemory: 2000MB\ncpus: 4\nbattery: 100%\n"
            f"position: [{3 * i}, 0]\nrssi: -45dBm\n"
        )
    return folder


def clients(lab: RunningLab) -> dict[str, AgentClient]:
    """One API client per robot (with its token)."""
    return {r.name: AgentClient(str(r.api), r.token) for r in lab.lab.robots}


def all_active(doc: dict[str, Any]) -> bool:
    comps = doc.get("components") or []
    return len(comps) == len(COMPONENTS) and all(c.get("state") == "active" for c in comps)


def deploy_runs(lab: RunningLab, reserve_mb: int, runs: int) -> list[float]:
    """Seconds from POST /v1/deploy to all ACTIVE, `runs` times (undeploying in between)."""
    api = clients(lab)
    entry = api["robot-2"]
    wait_for(lambda: entry.get("/v1/status"), lambda d: d["allocator"]["name"], "allocator", 30)
    system = parse_system(system_text(reserve_mb), f"<paper reserve {reserve_mb}>")
    times = []
    for _ in range(runs):
        t0 = time.perf_counter()
        entry.post("/v1/deploy", {"system": system.to_json()})
        wait_for(lambda: entry.get("/v1/status"), all_active, "all ACTIVE", 120)
        times.append(time.perf_counter() - t0)
        entry.post("/v1/undeploy", {})
        wait_for(
            lambda: [i for c in api.values() for i in c.get("/v1/instances")],
            lambda rows: rows == [],
            "hosts stopped",
            60,
        )
        for client in api.values():  # every agent's view (the allocator's too) shows the
            wait_for(  # memory back: records are sampled every second and gossiped
                partial(client.get, "/v1/members"),
                lambda ms: all((m.get("metrics") or {}).get("mem_free", 0) > MEM_BACK for m in ms),
                "free memory back in every agent's view",
                30,
            )
    return times


def election_once(lab: RunningLab) -> float:
    """Seconds from SIGKILL of the allocator's agent to all survivors naming a new one."""
    api = clients(lab)
    doc = wait_for(
        lambda: api["robot-1"].get("/v1/status"),
        lambda d: d["allocator"]["name"] is not None,
        "an allocator",
        30,
    )
    old, epoch = doc["allocator"]["name"], doc["allocator"]["epoch"]
    for name, c in api.items():  # everyone agrees before the kill
        wait_for(partial(c.get, "/v1/status"), lambda d: d["allocator"]["name"] == old, name, 10)
    pid = lab.procs[old].pid
    survivors = {n: c for n, c in api.items() if n != old}
    t0 = time.perf_counter()
    os.killpg(pid, signal.SIGKILL)

    def views() -> set[tuple[str | None, int]]:
        return {
            (d["allocator"]["name"], d["allocator"]["epoch"])
            for d in (c.get("/v1/status") for c in survivors.values())
        }

    def agreed(v: set[tuple[str | None, int]]) -> bool:
        return len(v) == 1 and next(iter(v))[0] not in (None, old) and next(iter(v))[1] > epoch

    wait_for(views, agreed, "a new allocator known by all", 30)
    return time.perf_counter() - t0


def summary(xs: list[float]) -> dict[str, float]:
    s = sorted(xs)
    return {
        "median_s": round(statistics.median(s), 3),
        "min_s": round(s[0], 3),
        "max_s": round(s[-1], 3),
        "runs": len(s),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--json", type=Path, metavar="PATH", help="write the figures as JSON")
    p.add_argument("--runs", type=int, default=5, help="deploys per reserve value")
    p.add_argument("--reserve", default="0,500", help="reserve_mb values, comma-separated")
    p.add_argument("--kills", type=int, default=3, help="allocator kills (a fresh lab each)")
    p.add_argument("--preset", default="lan", help="timer preset of the agents (lan, fast_test)")
    args = p.parse_args(argv)
    reserves = [int(x) for x in args.reserve.split(",") if x.strip()]
    figures: dict[str, Any] = {"preset": args.preset, "deploy": {}, "election": None}
    with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-deploy-") as tmp:
        root = Path(tmp)
        files = robot_files(root)
        options = UpOptions(3, root / "lab", preset=args.preset, robot_files=files, timeout=30)
        lab = start_lab(options, say=lambda _: None)
        try:
            for reserve in reserves:
                times = deploy_runs(lab, reserve, args.runs)
                figures["deploy"][str(reserve)] = {**summary(times), "all_s": times}
        finally:
            lab.stop(grace=5)
        kills = []
        for k in range(args.kills):
            opts = UpOptions(3, root / f"lab-e{k}", preset=args.preset, robot_files=files)
            lab = start_lab(opts, say=lambda _: None)
            try:
                kills.append(election_once(lab))
            finally:
                lab.stop(grace=5)
        if kills:
            figures["election"] = {**summary(kills), "all_s": kills}
    print(f"{'measure':<44} {'median':>8} {'min':>8} {'max':>8} {'runs':>5}  target")
    for reserve, f in figures["deploy"].items():
        target = f"<= {TARGET_DEPLOY_S:.1f} s" if reserve == "0" else "paper ~16 s (RPi 4)"
        label = f"deploy -> 5 ACTIVE, reserve_mb {reserve}"
        print(
            f"{label:<44} {f['median_s']:>7.3f}s {f['min_s']:>7.3f}s {f['max_s']:>7.3f}s"
            f" {f['runs']:>5}  {target}"
        )
    if figures["election"]:
        f = figures["election"]
        label = "allocator SIGKILL -> new one known by all (3)"
        print(
            f"{label:<44} {f['median_s']:>7.3f}s {f['min_s']:>7.3f}s {f['max_s']:>7.3f}s"
            f" {f['runs']:>5}  (report)"
        )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
