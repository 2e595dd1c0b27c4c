#!/usr/bin/env python3
"""How long agents take to exit after SIGTERM when a whole lab stops together.

Starts `--labs` labs of `--robots` real agents (lan preset, one at a time), optionally under
`--load` busy-loop processes, and SIGTERMs every agent of a lab at once (a fleet-wide stop: each
agent sees its peers leave while it stops itself). Reports, per agent, the seconds from SIGTERM to
its exit, its exit code, and how many did not exit within `--limit` seconds (they are then
SIGKILLed and counted). A stop that overruns the agent's own deadline exits with 1 and logs what
it waited for: those are counted apart.

    .venv/bin/python tools/bench_stop.py --labs 100 --load 2 --json /tmp/stop.json
"""

from __future__ import annotations

import argparse
import json
import multiprocessing
import os
import signal
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sdrpeer.lab.up import UpOptions, start_lab


def _spin() -> None:
    while True:
        pass


def stop_lab(procs: dict[str, Any], limit: float) -> list[tuple[str, float | None, int | None]]:
    """SIGTERM every agent at once; (name, seconds to exit or None, exit code) each."""
    t0 = time.monotonic()
    for proc in procs.values():
        os.kill(proc.pid, signal.SIGTERM)
    out: dict[str, tuple[float | None, int | None]] = {}
    while len(out) < len(procs) and time.monotonic() - t0 < limit:
        for name, proc in procs.items():
            if name not in out and proc.poll() is not None:
                out[name] = (time.monotonic() - t0, proc.returncode)
        time.sleep(0.005)
    for name, proc in procs.items():
        if name not in out:
            out[name] = (None, None)
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return [(n, t, rc) for n, (t, rc) in out.items()]


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--labs", type=int, default=20)
    p.add_argument("--robots", type=int, default=3)
    p.add_argument("--load", type=int, default=0, help="busy-loop processes competing (default 0)")
    p.add_argument("--limit", type=float, default=3.0, help="seconds an agent may take (3)")
    p.add_argument("--json", type=Path, metavar="PATH")
    args = p.parse_args(argv)
    spinners = [multiprocessing.Process(target=_spin, daemon=True) for _ in range(args.load)]
    for spinner in spinners:
        spinner.start()
    times: list[float] = []
    late: list[str] = []
    overdue = 0
    try:
        with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-stop-") as tmp:
            for i in range(args.labs):
                root = Path(tmp) / f"lab-{i}"
                lab = start_lab(UpOptions(args.robots, root, preset="lan"), say=lambda _: None)
                for name, took, rc in stop_lab(lab.procs, args.limit):
                    if took is None:
                        late.append(f"lab-{i}/{name}")
                        continue
                    times.append(took)
                    overdue += rc == 1
                print(
                    f"  lab {i + 1}/{args.labs}: slowest {max(times[-args.robots :]):.2f} s",
                    flush=True,
                )
    finally:
        for spinner in spinners:
            spinner.kill()
    agents = args.labs * args.robots
    s = sorted(times)
    figures = {
        "agents": agents,
        "load_processes": args.load,
        "limit_s": args.limit,
        "not_exited_within_limit": len(late),
        "late": late,
        "overdue_exit_1": overdue,
        "median_s": round(statistics.median(s), 3) if s else None,
        "p99_s": round(s[min(len(s) - 1, int(0.99 * len(s)))], 3) if s else None,
        "max_s": round(s[-1], 3) if s else None,
    }
    print(
        f"\n{'agents':>7} {'load':>5} {'median':>8} {'p99':>8} {'max':>8} {'late':>5} {'exit 1':>7}"
    )
    print(
        f"{agents:>7} {args.load:>5} {figures['median_s']:>7}s {figures['p99_s']:>7}s"
        f" {figures['max_s']:>7}s {len(late):>5} {overdue:>7}   (late: no exit {args.limit:g} s"
        " after SIGTERM; exit 1: the agent's own deadline ran out)"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
