#!/usr/bin/env python3
"""How long `sdrpeer members|status|instances --json` take, run as a user runs them.

Starts a real lab (`sdrpeer lab up`'s code, `--robots` agents, its default preset unless
`--preset`), deploys `--deploy FILE` on it (default: the paper's small system, ten hosts with
their standbys, so that `status` and `instances` have rows; `--no-deploy` for an empty fleet),
then runs each command `--n` times as a real subprocess (the `sdrpeer` console script next to
this Python, else `python -m sdrpeer`), the commands interleaved round by round so that a busy
moment of the machine falls on all of them alike. For every run it takes the wall time (spawn to
exit) and the CPU time the child used (user + system, from `getrusage(RUSAGE_CHILDREN)`), and
checks the exit code and that the output is JSON. The commands run with Python's bytecode cache
on (in a private `PYTHONPYCACHEPREFIX`, warmed by one run first), as an installed package runs;
`--no-bytecode-cache` runs them with `PYTHONDONTWRITEBYTECODE=1`, every module compiled from
source at every call (what a read-only checkout or this sandbox does). Two baselines put the
figures in context: a
bare interpreter start (`python -c pass`, the floor of any command) and the HTTP request alone
(the same GET made in this process with `sdrpeer.client`, i.e. the agent's side). Prints a
table of p50/p95 per command, the target line (issue 18: p50 <= 0.2 s wall on a 5-robot lab)
and writes the figures with `--json`.

    .venv/bin/python tools/bench_cli.py --robots 5 --n 30 --json /tmp/cli.json
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sdrpeer.client import AgentClient, resolve_endpoint
from sdrpeer.config import LAB_PRESET, PRESET_NAMES
from sdrpeer.lab.up import UpOptions, start_lab

ROOT = Path(__file__).resolve().parent.parent
DEFAULT_SYSTEM = ROOT / "examples" / "paper" / "system-small.yaml"
COMMANDS = ("members", "status", "instances")
PATHS = {"members": "/v1/members", "status": "/v1/status", "instances": "/v1/instances"}
TARGET_P50_S = 0.2


def sdrpeer_argv() -> list[str]:
    """How a user starts the command line: the console script when installed, else -m."""
    script = Path(sys.executable).with_name("sdrpeer")
    return [str(script)] if script.exists() else [sys.executable, "-m", "sdrpeer"]


def child_env(pycache: Path | None) -> dict[str, str]:
    """The commands' environment: bytecode cached under `pycache`, or (None) never written."""
    env = dict(os.environ)
    env.pop("PYTHONPYCACHEPREFIX", None)
    if pycache is None:
        env["PYTHONDONTWRITEBYTECODE"] = "1"
    else:
        env.pop("PYTHONDONTWRITEBYTECODE", None)
        env["PYTHONPYCACHEPREFIX"] = str(pycache)
    return env


def timed_run(argv: list[str], env: dict[str, str] | None = None) -> tuple[float, float, str]:
    """Run `argv` to its end: (wall s, child CPU s, stdout); RuntimeError if it failed."""
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t0 = time.perf_counter()
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, check=False, env=env)
    wall = time.perf_counter() - t0
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    if done.returncode != 0:
        raise RuntimeError(f"{' '.join(argv)} exited {done.returncode}: {done.stderr.strip()}")
    return wall, cpu, done.stdout


def timed_call(call: Callable[[str], Any], arg: str) -> float:
    """Wall seconds of one call made in this process."""
    t0 = time.perf_counter()
    call(arg)
    return time.perf_counter() - t0


def quantiles(values: list[float]) -> dict[str, float]:
    """p50 and p95 (nearest rank) of `values`, in seconds rounded to the millisecond."""
    s = sorted(values)
    p95 = s[max(0, math.ceil(0.95 * len(s)) - 1)]
    return {"p50_s": round(statistics.median(s), 4), "p95_s": round(p95, 4)}


def deploy(lab_dir: Path, system: Path) -> None:
    """`sdrpeer deploy FILE --wait` on the lab, as a user would."""
    argv = [*sdrpeer_argv(), "deploy", str(system), "--wait", "--timeout", "180"]
    done = subprocess.run(
        [*argv, "--lab-dir", str(lab_dir)], capture_output=True, text=True, timeout=240, check=False
    )
    if done.returncode != 0:
        raise RuntimeError(f"deploy failed ({done.returncode}): {done.stderr or done.stdout}")


def measure(
    lab_dir: Path, n: int, commands: tuple[str, ...], env: dict[str, str]
) -> dict[str, Any]:
    """Every command `n` times (interleaved), plus the two baselines."""
    base = sdrpeer_argv()
    for command in commands:  # warms the bytecode cache (when there is one)
        timed_run([*base, command, "--json", "--lab-dir", str(lab_dir)], env)
    wall: dict[str, list[float]] = {c: [] for c in ("python -c pass", *commands)}
    cpu: dict[str, list[float]] = {c: [] for c in wall}
    found = resolve_endpoint(None, None, lab_dir, {})
    client = AgentClient(found.api, found.token)
    request: dict[str, list[float]] = {c: [] for c in commands}
    for _ in range(n):
        w, c, _out = timed_run([sys.executable, "-c", "pass"], env)
        wall["python -c pass"].append(w)
        cpu["python -c pass"].append(c)
        for command in commands:
            w, c, out = timed_run([*base, command, "--json", "--lab-dir", str(lab_dir)], env)
            json.loads(out)  # the command answered, with JSON
            wall[command].append(w)
            cpu[command].append(c)
            request[command].append(timed_call(client.get, PATHS[command]))
    rows: dict[str, Any] = {}
    for name, walls in wall.items():
        rows[name] = {
            "n": len(walls),
            "wall": quantiles(walls),
            "cpu": quantiles(cpu[name]),
            **({"request": quantiles(request[name])} if name in request else {}),
        }
    return rows


def print_table(rows: dict[str, Any], robots: int, deployed: str | None, cached: bool) -> list[str]:
    """The table and the target line; returns the commands that missed the target."""
    fleet = f"{robots} robots, {'system ' + deployed if deployed else 'nothing deployed'}"
    pyc = "bytecode cached" if cached else "no bytecode cache"
    print(f"\nsdrpeer CLI, {fleet}, {pyc} (seconds; req: the same GET made in-process)")
    head = ("command", "n", "wall p50", "wall p95", "cpu p50", "cpu p95", "req p50", "req p95")
    print(f"{head[0]:<16}{head[1]:>4}" + "".join(f"{h:>10}" for h in head[2:]))
    for name, row in rows.items():
        req = row.get("request") or {}
        cells = [
            row["wall"]["p50_s"],
            row["wall"]["p95_s"],
            row["cpu"]["p50_s"],
            row["cpu"]["p95_s"],
            req.get("p50_s"),
            req.get("p95_s"),
        ]
        text = "".join(f"{'-' if v is None else f'{v:.3f}':>10}" for v in cells)
        print(f"{name:<16}{row['n']:>4}{text}")
    missed = [c for c in COMMANDS if c in rows and rows[c]["wall"]["p50_s"] > TARGET_P50_S]
    verdict = "met" if not missed else f"MISSED by {', '.join(missed)}"
    print(f"target: p50 <= {TARGET_P50_S:g} s wall for members|status|instances --json: {verdict}")
    return missed


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=5, help="agents in the lab (default 5)")
    p.add_argument("--n", type=int, default=30, help="runs of each command (default 30)")
    p.add_argument("--preset", choices=PRESET_NAMES, help=f"the lab's (default {LAB_PRESET})")
    p.add_argument("--deploy", type=Path, default=DEFAULT_SYSTEM, metavar="FILE")
    p.add_argument("--no-deploy", action="store_true", help="measure an empty fleet")
    p.add_argument("--commands", default=",".join(COMMANDS), help="comma-separated subset")
    p.add_argument(
        "--no-bytecode-cache", action="store_true", help="PYTHONDONTWRITEBYTECODE=1 (this sandbox)"
    )
    p.add_argument("--json", type=Path, metavar="PATH", help="write the figures here")
    args = p.parse_args(argv)
    commands = tuple(c for c in args.commands.split(",") if c)
    unknown = sorted(set(commands) - set(COMMANDS))
    if unknown or not commands:
        p.error(f"--commands: unknown {', '.join(unknown) or '(none given)'}")
    system = None if args.no_deploy else args.deploy
    with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-cli-") as tmp:
        lab_dir = Path(tmp) / "lab"
        options = UpOptions(args.robots, lab_dir, preset=args.preset or LAB_PRESET, timeout=90)
        print(f"starting {args.robots} agents (preset {options.preset})", flush=True)
        running = start_lab(options, say=lambda _: None)
        try:
            if system is not None:
                print(f"deploying {system}", flush=True)
                deploy(lab_dir, system)
            print(f"running {', '.join(commands)} {args.n} times each", flush=True)
            pycache = None if args.no_bytecode_cache else Path(tmp) / "pycache"
            rows = measure(lab_dir, args.n, commands, child_env(pycache))
        finally:
            running.stop()
    cached = not args.no_bytecode_cache
    missed = print_table(rows, args.robots, system.name if system else None, cached)
    if args.json:
        figures = {
            "robots": args.robots,
            "preset": options.preset,
            "system": None if system is None else str(system),
            "runs": args.n,
            "argv": sdrpeer_argv(),
            "bytecode_cache": cached,
            "target_p50_s": TARGET_P50_S,
            "missed": missed,
            "commands": rows,
        }
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(figures, indent=2))
    return 0


if __name__ == "__main__":
    sys.exit(main())
