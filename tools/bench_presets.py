#!/usr/bin/env python3
"""Does a preset hold on a busy machine? False suspicions, deaths and elections of a quiet lab.

For each preset of `--presets` (default: every one), starts a real lab of `--robots` agents on
this machine, deploys `--deploy FILE` (default: the paper's small system, ten component hosts
competing for the CPU with the agents; `--no-deploy` for agents alone), optionally under `--load`
busy-loop processes, and leaves it alone for `--seconds`. Nothing fails in that time, so every
`member.suspect` is a false suspicion, every `member.dead` a false death and every change of the
allocator (an `election` event after the first leader) a flap. Counted from every agent's own
event log (`GET /v1/events`), from the moment the deployment is ACTIVE. Prints a table per
preset and writes the figures with `--json`.

    .venv/bin/python tools/bench_presets.py --robots 5 --seconds 120 --json /tmp/presets.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sdrpeer.agent.tuning import PRESETS
from sdrpeer.client import AgentClient
from sdrpeer.eventlog import EventKind
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SYSTEM = ROOT / "examples" / "paper" / "system-small.yaml"
COUNTED = {
    EventKind.MEMBER_SUSPECT: "suspicions",
    EventKind.MEMBER_DEAD: "deaths",
    EventKind.ELECTION: "allocator_changes",
}


def _spin() -> None:
    while True:
        pass


def clients(running: RunningLab) -> dict[str, AgentClient]:
    """Every robot's API client (with its token)."""
    return {
        r.name: AgentClient(str(r.api), r.token, timeout=10.0)
        for r in running.lab.robots
        if r.api is not None
    }


def last_ids(agents: dict[str, AgentClient]) -> dict[str, int]:
    """The id of each agent's newest event (events after it are counted)."""
    out: dict[str, int] = {}
    for name, client in agents.items():
        since = 0
        for _ in range(1000):  # bounded: 500 events a page
            batch = client.events(since=since, limit=500)
            if not batch:
                break
            since = int(batch[-1]["id"])
        out[name] = since
    return out


def counted(agents: dict[str, AgentClient], since: dict[str, int]) -> dict[str, Any]:
    """The counted events of every agent after `since`, by kind, and their details."""
    totals = dict.fromkeys(COUNTED.values(), 0)
    seen: list[str] = []
    for name, client in agents.items():
        after = since[name]
        for _ in range(1000):
            batch = client.events(since=after, limit=500)
            if not batch:
                break
            after = int(batch[-1]["id"])
            for event in batch:
                label = COUNTED.get(event["kind"])
                if label is not None:
                    totals[label] += 1
                    seen.append(f"{name}: {event['kind']} {json.dumps(event['detail'])[:120]}")
    return {**totals, "events": seen}


def soak(
    preset: str, robots: int, system: Path | None, seconds: float, root: Path
) -> dict[str, Any]:
    """One quiet lab of `preset`: the counts over `seconds`."""
    lab_dir = root / f"lab-{preset}"
    running = start_lab(UpOptions(robots, lab_dir, preset=preset, timeout=120), say=lambda _: None)
    try:
        if system is not None:
            argv = [sys.executable, "-m", "sdrpeer", "deploy", str(system), "--wait"]
            done = subprocess.run(
                [*argv, "--timeout", "180", "--lab-dir", str(lab_dir)],
                capture_output=True,
                text=True,
                timeout=240,
                check=False,
            )
            if done.returncode != 0:
                raise RuntimeError(f"deploy failed: {done.stderr or done.stdout}")
        agents = clients(running)
        since = last_ids(agents)
        t0 = time.monotonic()
        while time.monotonic() - t0 < seconds and not running.problems():
            time.sleep(1.0)  # the lab is left alone: nothing to poll for
        found = counted(agents, since)
        found["agents_exited"] = running.problems()
        found["seconds"] = round(time.monotonic() - t0, 1)
        return found
    finally:
        running.stop()


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--presets", default=",".join(PRESETS), help="comma-separated (default all)")
    p.add_argument("--robots", type=int, default=5)
    p.add_argument("--seconds", type=float, default=120.0, help="quiet time per preset (120)")
    p.add_argument("--deploy", type=Path, default=DEFAULT_SYSTEM, metavar="FILE")
    p.add_argument("--no-deploy", action="store_true", help="agents alone")
    p.add_argument("--load", type=int, default=0, help="busy-loop processes competing (0)")
    p.add_argument("--json", type=Path, metavar="PATH")
    args = p.parse_args(argv)
    presets = [n for n in args.presets.split(",") if n]
    unknown = [n for n in presets if n not in PRESETS]
    if unknown or not presets:
        p.error(f"--presets: unknown {', '.join(unknown) or '(none given)'}")
    system = None if args.no_deploy else args.deploy
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(args.load)]
    for spinner in spinners:
        spinner.start()
    results: dict[str, Any] = {}
    try:
        with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-presets-") as tmp:
            for preset in presets:
                print(f"{preset}: {args.robots} robots, {args.seconds:g} s quiet", flush=True)
                results[preset] = soak(preset, args.robots, system, args.seconds, Path(tmp))
                for line in results[preset]["events"][:20]:
                    print(f"  {line}")
    finally:
        for spinner in spinners:
            spinner.kill()
    what = f"system {system.name}" if system else "no system"
    print(f"\n{args.robots} robots, {what}, load {args.load}: events in a quiet lab (all false)")
    print(f"{'preset':<12}{'seconds':>9}{'suspicions':>12}{'deaths':>8}{'allocator changes':>19}")
    for preset, r in results.items():
        print(
            f"{preset:<12}{r['seconds']:>9}{r['suspicions']:>12}{r['deaths']:>8}"
            f"{r['allocator_changes']:>19}"
        )
    if args.json:
        figures = {
            "robots": args.robots,
            "system": None if system is None else str(system),
            "load_processes": args.load,
            "presets": results,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
