"""Fleet benchmark in the simulator: the real agent's gossip at 100, 1,000 and 5,000 robots.

Usage: python tools/bench_sim_fleet.py [--sizes 10,25,100,1000,5000] [--window 20]
                                       [--loss-sizes 100,1000] [--json out.json] [--quick]

How it works: `sdrpeer.sim.agents.AgentFleet` runs, for every robot, the real membership core
and what the real agent does with it every second (metrics, CPU average, link summary, the
publisher, the record and vitals codecs); tests/test_sim_calibration.py shows its bytes per agent
within 25 % of real agents at N = 10 and 25. Each size starts as a fleet that has already
converged (every robot's first record held by all: the join storm of thousands of robots is not
what an idle fleet costs, and the simulator could not afford it), then:
- idle: datagram bytes each robot sends per second over `--window` virtual seconds (mean, max),
  as the simulator counts them (the codec's datagram: header included) and "on the wire" (plus
  28 bytes of IP and UDP headers per datagram, as the real benchmark's iptables counters see);
  records and vitals revisions published per robot per second;
- failure detection: three robots killed 10 s apart; per death, the time until every running
  robot reports it DEAD (median and max);
- with `--loss-sizes`: 30 % loss on every link for `--window` seconds, no robot killed: false
  suspicions and deaths, and the bytes per robot.
The robots' churn is the "field" profile: CPU jumping 15 points every ~10 s, a battery draining
1 %/min (swapped at 5 %; its crossings of the election's health steps make records), free
memory moving now and then, on a Wi-Fi-like network (1 ms + 0-4 ms one way). Links are summarised
every sample up to 500 robots, every 10th above (`AgentFleet.summary_every`).
"""

from __future__ import annotations

import argparse
import json
import statistics
import sys
import time
from pathlib import Path
from typing import Any

from sdrpeer.gossip.config import lan
from sdrpeer.gossip.messages import DEAD, SUSPECT
from sdrpeer.sim.agents import AgentFleet, Churn

IP_UDP = 28
FIELD = Churn(cpu_jumps_per_s=0.1, battery=True, drain_pct_per_min=1.0, mem_moves_per_s=0.02)
TARGETS = {"bytes_per_s_1000": 3000.0, "detect_median_s": 2.0, "false_deaths": 0}


def say(text: str) -> None:
    print(text, flush=True)


def fleet(n: int, seed: int) -> AgentFleet:
    f = AgentFleet(n, lan(), FIELD, seed=seed, summary_every=1 if n <= 500 else 10)
    f.start(converged=True)
    f.cluster.run_until(10.0)  # every agent sampled, probes under way
    return f


def idle(f: AgentFleet, window: float) -> dict[str, Any]:
    c = f.cluster
    b0, d0, p0 = list(c.sent_bytes), list(c.sent_datagrams), f.published()
    c.run_until(c.now + window)
    n = len(c.names)
    payload = [(b - a) / window for a, b in zip(b0, c.sent_bytes, strict=True)]
    grams = [(b - a) / window for a, b in zip(d0, c.sent_datagrams, strict=True)]
    wire = [p + IP_UDP * g for p, g in zip(payload, grams, strict=True)]
    p1 = f.published()
    return {
        "bytes_per_s_mean": round(statistics.mean(payload), 1),
        "bytes_per_s_max": round(max(payload), 1),
        "wire_bytes_per_s_mean": round(statistics.mean(wire), 1),
        "wire_bytes_per_s_max": round(max(wire), 1),
        "datagrams_per_s_mean": round(statistics.mean(grams), 2),
        "records_per_robot_per_s": round((p1["record"] - p0["record"]) / window / n, 4),
        "vitals_per_robot_per_s": round((p1["vitals"] - p0["vitals"]) / window / n, 4),
    }


def detection(f: AgentFleet, deaths: int) -> dict[str, Any]:
    c = f.cluster
    times: list[float] = []
    for k in range(deaths):
        victim = c.names[1 + (k * 7919) % (len(c.names) - 1)]
        c.kill(victim)
        t_kill = c.now
        c.run_until(t_kill + 10.0)
        seen = c.trace.first_seen_by(victim, DEAD, after=t_kill)
        running = [n for n in c.up_names() if n != victim]
        if all(n in seen for n in running):
            times.append(max(seen[n] for n in running) - t_kill)
    return {
        "detect_s": [round(t, 3) for t in times],
        "detect_median_s": round(statistics.median(times), 3) if times else None,
        "detect_max_s": round(max(times), 3) if times else None,
        "detected": f"{len(times)} of {deaths}",
    }


def lossy(f: AgentFleet, window: float, loss: float) -> dict[str, Any]:
    c = f.cluster
    c.set_loss(loss)
    start = c.now
    figures = idle(f, window)
    return {
        "loss": loss,
        "false_suspicions": len(c.trace.false_reports(SUSPECT, after=start)),
        "false_deaths": len(c.trace.false_deaths(after=start)),
        "bytes_per_s_mean": figures["bytes_per_s_mean"],
        "wire_bytes_per_s_mean": figures["wire_bytes_per_s_mean"],
    }


def run(args: argparse.Namespace) -> dict[str, Any]:
    rows = []
    for n in args.sizes:
        t0 = time.perf_counter()
        f = fleet(n, args.seed)
        row: dict[str, Any] = {"n": n, **idle(f, args.window)}
        row.update(detection(f, args.deaths))
        say(
            f"  N={n}: {row['wire_bytes_per_s_mean']:,.0f} B/s per robot on the wire "
            f"({row['bytes_per_s_mean']:,.0f} datagram bytes), records "
            f"{row['records_per_robot_per_s']}/robot/s, vitals {row['vitals_per_robot_per_s']}"
            f"/robot/s, detection median {row['detect_median_s']} s "
            f"({time.perf_counter() - t0:.0f} s wall)"
        )
        if n in args.loss_sizes:
            t1 = time.perf_counter()
            g = fleet(n, args.seed + 1)
            row["loss_30"] = lossy(g, args.window, 0.3)
            say(
                f"  N={n} at 30 % loss: {row['loss_30']['false_deaths']} false deaths, "
                f"{row['loss_30']['false_suspicions']} false suspicions, "
                f"{row['loss_30']['wire_bytes_per_s_mean']:,.0f} B/s "
                f"({time.perf_counter() - t1:.0f} s wall)"
            )
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
    return {"window_s": args.window, "profile": "field", "rows": rows, "targets": TARGETS}


def table(doc: dict[str, Any]) -> str:
    lines = [
        f"\n{'N':>6} {'B/s wire':>9} {'B/s max':>8} {'datagram B/s':>12} {'records':>8} "
        f"{'vitals':>7} {'detect med':>10} {'max':>6} {'30% loss: false deaths':>23}"
    ]
    for r in doc["rows"]:
        loss = r.get("loss_30")
        fd = "-" if loss is None else f"{loss['false_deaths']} ({loss['false_suspicions']} susp.)"
        lines.append(
            f"{r['n']:>6} {r['wire_bytes_per_s_mean']:>9,.0f} {r['wire_bytes_per_s_max']:>8,.0f} "
            f"{r['bytes_per_s_mean']:>12,.0f} {r['records_per_robot_per_s']:>8} "
            f"{r['vitals_per_robot_per_s']:>7} {r['detect_median_s']!s:>10} "
            f"{r['detect_max_s']!s:>6} {fd:>23}"
        )
    big = next((r for r in doc["rows"] if r["n"] == 1000), None)
    if big is not None:
        ok = big["wire_bytes_per_s_mean"] <= TARGETS["bytes_per_s_1000"]
        lines.append(
            f"\nN=1000: {big['wire_bytes_per_s_mean']:,.0f} B/s per robot on the wire "
            f"(target <= 3,000): {'met' if ok else 'NOT met'}; detection median "
            f"{big['detect_median_s']} s (target <= 2)"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--sizes", default="10,25,100,1000,5000")
    p.add_argument("--loss-sizes", default="100,1000")
    p.add_argument("--window", type=float, default=20.0, help="virtual seconds measured")
    p.add_argument("--deaths", type=int, default=3)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--json", type=Path)
    p.add_argument("--quick", action="store_true", help="N=10 and 60, short windows")
    args = p.parse_args(argv)
    if args.quick:
        args.sizes, args.loss_sizes, args.window, args.deaths = "10,60", "60", 10.0, 2
    args.sizes = [int(x) for x in str(args.sizes).split(",") if x]
    args.loss_sizes = [int(x) for x in str(args.loss_sizes).split(",") if x]
    t0 = time.perf_counter()
    doc = run(args)
    doc["quick"] = args.quick
    say(table(doc))
    say(f"({time.perf_counter() - t0:.0f} s)")
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
