#!/usr/bin/env python3
"""Rotating the cluster key of a running fleet with `sdrpeer keygen` and `sdrpeer key ...`:
suspicions during the rotation, and how long the fleet takes to switch its primary key.

Usage: python tools/bench_keys.py [--robots 5] [--runs 3] [--netns] [--preset lan] [--settle 10]
       [--json PATH]

How it works: one lab of `--robots` real agents (`sdrpeer lab up`; `--netns`: each robot in its
own network namespace, root) is started, then each run rotates its key with the real command
line, as an operator would: `sdrpeer keygen > new.key`, `sdrpeer key add new.key`, `sdrpeer key
primary ID`, `sdrpeer key retire OLD`, each timed (the agent asked answers once every robot took
the change, so the `primary` command's time is the time for the whole fleet to switch its
sealing key, Python's start-up included; the agents' `keys.reloaded` events give the spread from
the first robot sealing with the new key to the last). Afterwards `sdrpeer key list --json` must
show every robot on the new key alone, and every agent's event log, read from before the run, is
searched, after `--settle` seconds of the fleet on the new key alone, for `member.suspect` and
`member.dead` (the target: none; every robot must still see every robot alive), and its
`unauthenticated` and `unknown_key` rejections counted (none expected: every datagram opens at
every step). The table prints medians over the runs; `--json` writes every run.
"""

from __future__ import annotations

import argparse
import json
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
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab  # noqa: E402

BAD_KINDS = ("member.suspect", "member.dead")
REJECTIONS = ("unauthenticated", "unknown_key")


def cli(lab_dir: Path, *args: str, stdout: Any = subprocess.PIPE) -> tuple[int, str, float]:
    """(exit code, output, seconds) of one real `sdrpeer` command against the lab (a `key`
    command asks the lab's first robot, with its token from the lab file)."""
    where = ["--lab-dir", str(lab_dir)] if args[0] == "key" else []
    t0 = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", *args, *where],
        stdout=stdout,
        stderr=subprocess.PIPE,
        text=True,
        timeout=120,
        check=False,
        cwd=ROOT,
    )
    out = done.stdout if isinstance(done.stdout, str) else ""
    return done.returncode, out + done.stderr, time.monotonic() - t0


def ok(step: str, result: tuple[int, str, float]) -> tuple[str, float]:
    """(output, seconds) of a command that must succeed; RuntimeError with its output else."""
    code, text, took = result
    if code != 0:
        raise RuntimeError(f"{step} exited with {code}: {text}")
    return text, took


def marks(running: RunningLab) -> dict[str, tuple[int, dict[str, int]]]:
    """Each agent's newest event id and rejection counters."""
    out = {}
    for robot in running.lab.robots:
        client = AgentClient(str(robot.api), timeout=5)
        events = client.events(since=0, limit=10_000)
        last = max((int(e["id"]) for e in events), default=0)
        out[robot.name] = (last, dict(client.agent()["rejected"]))
    return out


def trouble_since(
    running: RunningLab, before: dict[str, tuple[int, dict[str, int]]]
) -> tuple[list[dict[str, Any]], dict[str, int]]:
    """Suspicions and deaths seen by any agent since `before`, and new key rejections."""
    bad: list[dict[str, Any]] = []
    rejected = dict.fromkeys(REJECTIONS, 0)
    for robot in running.lab.robots:
        client = AgentClient(str(robot.api), timeout=5)
        last, counts = before[robot.name]
        for event in client.events(since=last, limit=10_000):
            if event.get("kind") in BAD_KINDS:
                bad.append({"seen_by": robot.name, **event})
        now = client.agent()["rejected"]
        for reason in REJECTIONS:
            rejected[reason] += int(now.get(reason, 0)) - int(counts.get(reason, 0))
    return bad, rejected


def switch_times(running: RunningLab, before: dict[str, tuple[int, dict[str, int]]]) -> list[float]:
    """When each agent put the new primary in use (its `keys.reloaded` event, wall clock: the
    lab's agents share this machine's clock)."""
    out = []
    for robot in running.lab.robots:
        events = AgentClient(str(robot.api), timeout=5).events(since=before[robot.name][0])
        out += [
            float(e["ts"])
            for e in events
            if e.get("kind") == "keys.reloaded" and e["detail"].get("why") == "key primary"
        ]
    return out


def rotate(running: RunningLab, work: Path, settle: float) -> dict[str, Any]:
    """One rotation with the real command line, then `settle` seconds of the fleet on the new
    key alone; its figures."""
    lab_dir = running.lab_dir
    before = marks(running)
    listing = json.loads(cli(lab_dir, "key", "list", "--json")[1])
    old = sorted({k for d in listing["robots"].values() for k in d["keys"]})
    new_key = work / f"key-{time.monotonic_ns()}.key"
    with new_key.open("w") as out:
        _, keygen_s = ok("keygen", cli(lab_dir, "keygen", stdout=out))
    steps: dict[str, float] = {"keygen": keygen_s}
    text, steps["add"] = ok("key add", cli(lab_dir, "key", "add", str(new_key), "--json"))
    new_id = json.loads(text)["key_id"]
    asked = time.time()
    _, steps["primary"] = ok("key primary", cli(lab_dir, "key", "primary", new_id, "--json"))
    switched = switch_times(running, before)
    retire_s = 0.0
    for kid in old:
        retire_s += ok("key retire", cli(lab_dir, "key", "retire", kid, "--json"))[1]
    steps["retire"] = retire_s
    after = json.loads(cli(lab_dir, "key", "list", "--json")[1])
    on_new = sorted(
        name
        for name, doc in after["robots"].items()
        if doc.get("primary") == new_id and doc.get("keys") == [new_id]
    )
    time.sleep(settle)  # a robot left on a retired key would be suspected within this
    bad, rejected = trouble_since(running, before)
    alive = {
        robot.name: sum(
            m["state"] == "alive" for m in AgentClient(str(robot.api), timeout=5).members()
        )
        for robot in running.lab.robots
    }
    return {
        "alive_seen_after": alive,
        "new_key_id": new_id,
        "retired": old,
        "seconds": steps,
        "switch_primary_s": steps["primary"],
        "switch_spread_s": round(max(switched) - min(switched), 3),
        "switch_last_after_ask_s": round(max(switched) - asked, 3),
        "switched_robots": len(switched),
        "robots_on_new_key": len(on_new),
        "robots": len(running.lab.robots),
        "suspicions": sum(1 for e in bad if e["kind"] == "member.suspect"),
        "deaths": sum(1 for e in bad if e["kind"] == "member.dead"),
        "bad_events": bad,
        "rejected": rejected,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=5)
    p.add_argument("--runs", type=int, default=3)
    p.add_argument("--netns", action="store_true", help="each robot in a network namespace (root)")
    p.add_argument("--preset", default="lan", help="the agents' preset (default lan)")
    p.add_argument("--json", type=Path, metavar="PATH", help="write every run here")
    p.add_argument(
        "--settle",
        type=float,
        default=10.0,
        help="seconds watched after each retire before counting (default 10: several of the "
        "preset's probe timeouts, so a robot left on a retired key would be suspected)",
    )
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory(prefix="bench-keys-") as tmp:
        work = Path(tmp)
        options = UpOptions(
            args.robots, work / "lab", preset=args.preset, netns=args.netns, timeout=60
        )
        running = start_lab(options, say=lambda _: None)
        try:
            runs = [rotate(running, work, args.settle) for _ in range(args.runs)]
        finally:
            running.stop(grace=5)
    med = {
        k: statistics.median(r["seconds"][k] for r in runs)
        for k in ("keygen", "add", "primary", "retire")
    }
    print(
        f"key rotation of a {args.robots}-robot lab ({'netns' if args.netns else 'loopback'}, "
        f"preset {args.preset}), {args.runs} runs, medians:"
    )
    print(f"{'step':<28}{'seconds':>10}")
    for step, label in (
        ("keygen", "sdrpeer keygen"),
        ("add", "sdrpeer key add"),
        ("primary", "sdrpeer key primary (switch)"),
        ("retire", "sdrpeer key retire"),
    ):
        print(f"{label:<28}{med[step]:>10.3f}")
    total_bad = sum(r["suspicions"] + r["deaths"] for r in runs)
    print(f"{'suspicions (all runs)':<28}{sum(r['suspicions'] for r in runs):>10}")
    print(f"{'deaths (all runs)':<28}{sum(r['deaths'] for r in runs):>10}")
    print(f"{'key rejections (all runs)':<28}{sum(sum(r['rejected'].values()) for r in runs):>10}")
    spread = statistics.median(r["switch_spread_s"] for r in runs)
    last = statistics.median(r["switch_last_after_ask_s"] for r in runs)
    print(f"{'  first to last robot':<28}{spread:>10.3f}")
    print(f"{'  command start to last':<28}{last:>10.3f}")
    on_new = min(r["robots_on_new_key"] for r in runs)
    print(f"{'robots on the new key alone':<28}{on_new:>7}/{args.robots}")
    seen = min(n for r in runs for n in r["alive_seen_after"].values())
    print(f"{'alive seen by each, after':<28}{seen:>7}/{args.robots} (min, {args.settle:g} s on)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        doc = {
            "robots": args.robots,
            "netns": args.netns,
            "preset": args.preset,
            "median_s": med,
            "switch_primary_s_median": med["primary"],
            "switch_spread_s_median": spread,
            "switch_last_after_ask_s_median": last,
            "suspicions": sum(r["suspicions"] for r in runs),
            "deaths": sum(r["deaths"] for r in runs),
            "runs": runs,
        }
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0 if total_bad == 0 and on_new == args.robots else 1


if __name__ == "__main__":
    sys.exit(main())
