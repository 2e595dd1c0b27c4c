#!/usr/bin/env python3
"""Whether `lab down` stops everything after a `lab up` killed at any moment, and how long it takes.

Each of `--runs` runs starts `sdrpeer lab up --robots N` (real agents, in the foreground) as a
subprocess, SIGKILLs it after a delay drawn from a seeded uniform [0, `--kill-within`] s, so it
dies before, while or after spawning its agents, then runs `sdrpeer lab down` and looks in /proc
for any process that still names the lab directory in its command line or environment
(`sdrpeer.lab.procs.processes_naming`, independent of the mark `lab down` itself looks for).
Reports per run: the kill delay, the agents lab.json named and those running without being named
at that moment, `lab down`'s wall time and the survivors (then SIGKILLed); then totals. Exits
with 1 when anything survived. `--load N` adds busy-loop processes (the incident happened under
two). `--json FILE` writes the figures.

    .venv/bin/python tools/bench_lab_down.py --runs 20 --robots 3 --load 2 --json /tmp/down.json
"""

from __future__ import annotations

import argparse
import contextlib
import json
import multiprocessing
import os
import random
import signal
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sdrpeer.lab.files import read_lab
from sdrpeer.lab.procs import lab_processes, processes_naming, running_pids


def _spin() -> None:
    while True:
        pass


def _sdrpeer(*args: str) -> list[str]:
    return [sys.executable, "-m", "sdrpeer", *args]


def one_run(lab_dir: Path, robots: int, delay: float) -> dict[str, Any]:
    """Start a lab, kill its `lab up` after `delay` s, take it down; what happened."""
    up = subprocess.Popen(
        _sdrpeer("lab", "up", "--robots", str(robots), "--dir", str(lab_dir), "--timeout", "120"),
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    time.sleep(delay)  # a benchmark's chosen moment, not a wait for a condition
    up.kill()
    up.wait()
    lab = read_lab(lab_dir) if lab_dir.is_dir() else None
    recorded = len(running_pids(lab)) if lab is not None else 0
    running = len(lab_processes(lab_dir)) if lab_dir.is_dir() else 0
    t0 = time.monotonic()
    down = subprocess.run(
        _sdrpeer("lab", "down", "--dir", str(lab_dir)),
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    took = time.monotonic() - t0
    survivors = processes_naming(lab_dir)
    for line in survivors:
        with contextlib.suppress(ProcessLookupError):
            os.kill(int(line.split(":")[0]), signal.SIGKILL)
    return {
        "delay_s": round(delay, 3),
        "recorded": recorded,
        "unrecorded": max(0, running - recorded),
        "down_s": round(took, 3),
        "down_rc": down.returncode,
        "survivors": survivors,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--runs", type=int, default=10)
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--kill-within", type=float, default=4.0, metavar="S", help="(default 4)")
    p.add_argument("--load", type=int, default=0, help="busy-loop processes competing (default 0)")
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--json", type=Path, metavar="PATH")
    args = p.parse_args(argv)
    rng = random.Random(args.seed)
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(args.load)]
    for spinner in spinners:
        spinner.start()
    runs: list[dict[str, Any]] = []
    try:
        with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-down-") as tmp:
            print("run  killed at  recorded  unrecorded  down  survivors")
            for i in range(args.runs):
                run = one_run(Path(tmp) / f"lab-{i}", args.robots, rng.uniform(0, args.kill_within))
                runs.append(run)
                print(
                    f"{i:3d}  {run['delay_s']:7.2f} s  {run['recorded']:8d}  "
                    f"{run['unrecorded']:10d}  {run['down_s']:4.2f}s  {len(run['survivors']):9d}",
                    flush=True,
                )
    finally:
        for spinner in spinners:
            spinner.terminate()
    downs = [r["down_s"] for r in runs]
    figures = {
        "runs": len(runs),
        "robots": args.robots,
        "load": args.load,
        "kill_within_s": args.kill_within,
        "seed": args.seed,
        "runs_with_unrecorded_agents": sum(r["unrecorded"] > 0 for r in runs),
        "survivors": sum(len(r["survivors"]) for r in runs),
        "down_median_s": statistics.median(downs) if downs else None,
        "down_max_s": max(downs) if downs else None,
        "per_run": runs,
    }
    print(
        f"{figures['runs']} runs, {figures['runs_with_unrecorded_agents']} with agents lab.json "
        f"did not name when lab up died; survivors after lab down: {figures['survivors']}; "
        f"lab down median {figures['down_median_s']} s, max {figures['down_max_s']} s"
    )
    if args.json:
        args.json.write_text(json.dumps(figures, indent=2) + "\n")
    return 1 if figures["survivors"] else 0


if __name__ == "__main__":
    sys.exit(main())
