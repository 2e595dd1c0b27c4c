#!/usr/bin/env python3
"""A robot with only the cluster key and its configuration file (no seed address) joining a
fleet through mDNS, in the namespace lab (root): how long until the fleet has it.

Usage: sudo .venv/bin/python tools/bench_discovery.py [--robots 5] [--runs 5] [--python PY]
       [--json PATH]

How it works: a namespace lab of `--robots` robots is started with discovery on and no `--join`
at all (`UpOptions(discover=True)`: the lab itself forms by mDNS). Each run then stops the last
robot (SIGTERM: it leaves), waits until every other robot has it `left`, writes a configuration
file holding only its name, addresses, key file, data and robot files, `discover: true` and the
preset, and starts `sdrpeer agent --config FILE` in its namespace. Two times are measured, from
the process's spawn and from the moment its agent started (its `agent.start` event), to the first
moment when it sees every other robot alive and every other robot sees it alive (all polled every
50 ms). `--python` runs the joining robot with another interpreter, e.g. that of a fresh venv
holding only the wheel (`pip install dist/sdrpeer-*.whl`): then nothing of this tree is on its
path. The target: within 3 s. The table prints the medians and the worst; `--json` writes
every run.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from sdrpeer.client import AgentClient  # noqa: E402
from sdrpeer.errors import ApiError  # noqa: E402
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab  # noqa: E402

POLL = 0.05
LIMIT = 60.0


def states(api: str) -> dict[str, str]:
    """name -> state as one agent sees the fleet ({} while it does not answer)."""
    try:
        return {m["name"]: m["state"] for m in AgentClient(api, timeout=1).members()}
    except ApiError:
        return {}


def wait_for(what: str, check: Any, limit: float = LIMIT) -> float:
    """Poll `check()` until true; the monotonic time it first was. RuntimeError past `limit`."""
    end = time.monotonic() + limit
    while time.monotonic() < end:
        if check():
            return time.monotonic()
        time.sleep(POLL)
    raise RuntimeError(f"{what}: not within {limit:g} s")


def config_for(running: RunningLab, robot: str, path: Path) -> Path:
    """The robot's configuration file: no join address, discovery on."""
    assert running.net is not None
    entry = running.lab.robot(robot)
    assert entry is not None
    host = running.net.address(robot)
    options = running.options
    assert options is not None
    path.write_text(
        f"name: {robot}\n"
        f"bind: {host}:7946\n"
        f"api: {host}:8080\n"
        f"key-file: {running.lab.key_file}\n"
        f"token-file: {entry.data_dir}/token\n"
        f"data-dir: {entry.data_dir}\n"
        f"robot-file: {entry.data_dir}/robot.yaml\n"
        f"preset: {options.preset}\n"
        "discover: true\n"
    )
    return path


def join_once(
    running: RunningLab, robot: str, work: Path, python: str | None = None
) -> dict[str, Any]:
    """Stop `robot`, start it again from its configuration file only (with `python`, else this
    interpreter and this tree); the two times."""
    assert running.net is not None
    others = [r for r in running.lab.robots if r.name != robot]
    proc = running.procs[robot]
    proc.terminate()
    proc.wait(timeout=30)
    wait_for(
        f"{robot} left for every robot",
        lambda: all(states(str(r.api)).get(robot) in ("left", "dead") for r in others),
    )
    config = config_for(running, robot, work / f"{robot}.yaml")
    entry = running.lab.robot(robot)
    assert entry is not None
    api = f"http://{running.net.address(robot)}:8080"
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    if python is not None:
        env.pop("PYTHONPATH")
    wall0, t0 = time.time(), time.monotonic()
    with Path(entry.log).open("ab") as log:
        running.procs[robot] = subprocess.Popen(
            running.net.in_ns(
                robot, sys.executable, "-m", "sdrpeer", "agent", "--config", str(config)
            ),
            stdout=log,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            start_new_session=True,
            env=env,
            cwd=work,
        )
    entry.pid = running.procs[robot].pid
    names = {r.name for r in running.lab.robots}

    def whole() -> bool:
        mine = states(api)
        if {n for n, s in mine.items() if s == "alive"} != names:
            return False
        return all(states(str(r.api)).get(robot) == "alive" for r in others)

    t1 = wait_for(f"{robot} in the fleet", whole)
    events = AgentClient(api, timeout=5).events(since=0, limit=1000)
    started = [e["ts"] for e in events if e.get("kind") == "agent.start" and e["ts"] >= wall0 - 1]
    start_mono = t0 + (min(started) - wall0) if started else None
    return {
        "from_spawn_s": round(t1 - t0, 3),
        "from_agent_start_s": None if start_mono is None else round(t1 - start_mono, 3),
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=5)
    p.add_argument("--runs", type=int, default=5)
    p.add_argument("--preset", default="lan")
    p.add_argument("--python", metavar="PY", help="the joining robot's interpreter (a wheel venv)")
    p.add_argument("--json", type=Path, metavar="PATH")
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-discovery-") as tmp:
        work = Path(tmp)
        t0 = time.monotonic()
        options = UpOptions(
            args.robots, work / "lab", preset=args.preset, netns=True, discover=True, timeout=90
        )
        running = start_lab(options, say=lambda _: None)
        formed = time.monotonic() - t0
        try:
            runs = [
                join_once(running, f"robot-{args.robots}", work, args.python)
                for _ in range(args.runs)
            ]
        finally:
            running.stop(grace=5)
    spawn = [r["from_spawn_s"] for r in runs]
    agent = [r["from_agent_start_s"] for r in runs if r["from_agent_start_s"] is not None]
    print(
        f"mDNS join of robot-{args.robots} into a {args.robots}-robot namespace lab, "
        f"{args.runs} runs"
    )
    print(f"{'measured from':<24}{'median s':>10}{'worst s':>10}")
    print(f"{'process spawn':<24}{statistics.median(spawn):>10.3f}{max(spawn):>10.3f}")
    if agent:
        print(f"{'agent start':<24}{statistics.median(agent):>10.3f}{max(agent):>10.3f}")
    print(f"(the lab itself formed by mDNS alone, no --join: {formed:.1f} s for lab up)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        doc = {
            "robots": args.robots,
            "preset": args.preset,
            "lab_up_s": round(formed, 2),
            "runs": runs,
        }
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
