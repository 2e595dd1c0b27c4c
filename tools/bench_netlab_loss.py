"""False deaths under real packet loss: a namespace lab with loss on every link for minutes.

Usage (root): python tools/bench_netlab_loss.py [--robots 5] [--loss 30] [--minutes 10]
                                                [--preset lan] [--json out.json]

How it works: `sdrpeer lab up --netns` starts the robots, each in its own network namespace;
every robot then drops `--loss` % of the packets arriving at it (iptables `statistic`, so each
link loses that share in each direction: a probe and its ack cross two links). No robot is ever
stopped, so every `member.dead` any agent logs is a false death and every `member.suspect` a
false suspicion. At the end the figures are read from every agent's event log: false deaths
(target 0), false suspicions, refutations (a robot saying it is alive after a suspicion), the
loss the agents measured, and whether every robot still sees every other alive.
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError
from sdrpeer.lab.up import UpOptions, start_lab
from sdrpeer.netlab import net


def measure(args: argparse.Namespace) -> dict[str, Any]:
    with tempfile.TemporaryDirectory() as tmp:
        lab_dir = Path(tmp) / "lab"
        running = start_lab(
            UpOptions(args.robots, lab_dir, preset=args.preset, netns=True, timeout=60),
            say=lambda _: None,
        )
        try:
            plan = running.net
            assert plan is not None
            clients = {r.name: AgentClient(str(r.api), timeout=3) for r in running.lab.robots}
            for robot in plan.names():
                net.run(plan.loss(robot, args.loss / 100))
            t0 = time.monotonic()
            deadline = t0 + args.minutes * 60
            while time.monotonic() < deadline:
                time.sleep(min(10.0, max(0.0, deadline - time.monotonic())))
                print(f"  {time.monotonic() - t0:6.0f} s", flush=True)
            return figures(clients, args)
        finally:
            running.stop(grace=3)


def figures(clients: dict[str, AgentClient], args: argparse.Namespace) -> dict[str, Any]:
    """Deaths, suspicions and measured loss from every agent."""
    deaths: list[dict[str, Any]] = []
    suspicions = 0
    alive_everywhere = True
    losses: list[float] = []
    for name, client in clients.items():
        try:
            events = client.events(0, 10_000)
            members = client.members()
        except ApiError as exc:
            raise SystemExit(f"{name} does not answer: {exc}") from None
        deaths += [e for e in events if e["kind"] == "member.dead"]
        suspicions += sum(1 for e in events if e["kind"] == "member.suspect")
        alive_everywhere &= all(m["state"] == "alive" for m in members)
        me = next(m for m in members if m["name"] == name)
        losses += [
            float(v["loss"]) for v in (me.get("links") or {}).values() if v.get("loss") is not None
        ]
    return {
        "robots": args.robots,
        "loss_pct_per_link": args.loss,
        "minutes": args.minutes,
        "preset": args.preset,
        "false_deaths": len(deaths),
        "false_death_events": deaths[:10],
        "false_suspicions": suspicions,
        "all_alive_at_end": alive_everywhere,
        "measured_round_trip_loss_median": round(statistics.median(losses), 3) if losses else None,
    }


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=5)
    p.add_argument("--loss", type=float, default=30.0, help="percent dropped on every link")
    p.add_argument("--minutes", type=float, default=10.0)
    p.add_argument("--preset", default="lan")
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    net.require_tools()
    r = measure(args)
    print(
        f"{r['robots']} robots, {r['loss_pct_per_link']:g}% loss on every link, {r['minutes']:g} "
        f"min ({r['preset']}): false deaths {r['false_deaths']} (target 0), false suspicions "
        f"{r['false_suspicions']}, all alive at the end: {r['all_alive_at_end']}, measured "
        f"round-trip loss (median) {r['measured_round_trip_loss_median']}"
    )
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(r, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
