"""Placement benchmark: how many instances per second the allocation core places.

Usage: python tools/bench_placement.py [--json out.json] [--quick] [--seed N] [--runs N]

How it works: a seeded random cluster (200 robots: memory, CPU, battery, RSSI, positions on a
200 m square, a measured link between every pair) and a seeded random system (1,000 components
with CPU and memory needs, 2,000 connections with traffic, Table I and II thresholds all set) are
built once; then `sdrpeer.alloc.core.allocate` runs several times per strategy on that input and
the wall time of each call is measured (building the view is not timed: the agent builds it
from its gossip table). Placements per second = instances placed / median call time. Target:
>= 10,000/s; for scale, Nomad's C1M challenge placed 3,750 containers/s (on a whole cluster of
schedulers). `--quick` shrinks everything for the test suite.
"""

from __future__ import annotations

import argparse
import json
import random
import statistics
import sys
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.record.robot import LinkBounds, LinkStats, LinkSummary, Metrics
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    Requirements,
    SystemDef,
    Thresholds,
)

TARGET_PER_S = 10_000
NOMAD_C1M_PER_S = 3_750
MB = 1000**2
GB = 1000**3
STRATEGIES = ("first_fit", "objective")
THRESHOLDS = Thresholds(
    cpu_below_pct=90.0,
    mem_free_above_bytes=200 * MB,
    battery_above_pct=20.0,
    rssi_above_dbm=-75.0,
    jitter_below_ms=20.0,
    distance_below_m=150.0,
)


@dataclass(frozen=True)
class Size:
    """What to measure: the full benchmark or the quick smoke test."""

    robots: int = 200
    components: int = 1000
    connections: int = 2000
    runs: int = 7


FULL = Size()
QUICK = Size(robots=20, components=100, connections=200, runs=2)


def make_view(rng: random.Random, n: int) -> ClusterView:
    """`n` robots with random metrics, positions and a measured link to every other robot."""
    names = [f"robot-{k:03d}" for k in range(n)]
    robots = []
    for name in names:
        total = rng.choice((4, 8, 16)) * GB
        metrics = Metrics(
            cpu_pct=rng.uniform(0, 50),
            mem_total=total,
            mem_free=int(total * rng.uniform(0.3, 0.9)),
            battery_pct=rng.uniform(10, 100),
            rssi_dbm=rng.uniform(-80, -35),
            pos=(rng.uniform(0, 200), rng.uniform(0, 200)),
        )
        bad = {  # what a record lists: a few links past the bounds, exactly
            peer: LinkStats(
                rtt_ms=rng.uniform(1, 60),
                jitter_ms=rng.expovariate(1 / 8),
                loss=rng.uniform(0, 0.2),
            )
            for peer in rng.sample([p for p in names if p != name], min(3, len(names) - 1))
        }
        links = LinkSummary(
            peers=len(names) - 1,
            typical=LinkStats(rtt_ms=rng.uniform(1, 30), jitter_ms=2.0, loss=0.01),
            bad=len(bad),
            bounds=LinkBounds(rtt_ms=50.0, jitter_ms=10.0, loss=0.05),
            listed=bad,
        )
        robots.append(RobotView(name, metrics, links))
    return ClusterView(tuple(robots), origin=names[0])


def make_system(rng: random.Random, components: int, connections: int) -> SystemDef:
    """`components` components with random needs, `connections` random connections."""
    comps = tuple(
        ComponentDef(
            f"C{k:04d}",
            "python",
            "pkg.mod:Class",
            requires=Requirements(
                cpu_pct=rng.uniform(0.2, 3.0), mem_bytes=rng.randint(20, 300) * MB
            ),
        )
        for k in range(components)
    )
    conns = []
    for k in range(connections):
        a, b = rng.sample(range(components), 2)
        conns.append(
            ConnectionDef(
                f"C{a:04d}", f"out{k}", f"C{b:04d}", "in", traffic_bytes_per_s=rng.uniform(1e3, 1e6)
            )
        )
    return SystemDef("bench", comps, tuple(conns), AllocationDef(thresholds=THRESHOLDS))


def measure(system: SystemDef, view: ClusterView, strategy: str, runs: int) -> dict[str, Any]:
    """Median wall time of `allocate` over `runs` calls with `strategy`."""
    system = replace(system, allocation=replace(system.allocation, strategy=strategy))
    times = []
    placed = 0
    feasible = True
    for _ in range(runs):
        start = time.perf_counter()
        result = allocate(system, view, epoch=1, version=1, allocator=view.robots[0].name)
        times.append(time.perf_counter() - start)
        feasible = result.plan is not None
        placed = len(result.plan.placements) if result.plan is not None else 0
    median = statistics.median(times)
    robots_used = len({p.robot for p in result.plan.placements}) if result.plan else 0
    return {
        "strategy": strategy,
        "feasible": feasible,
        "placements": placed,
        "robots_used": robots_used,
        "runs_s": [round(t, 6) for t in times],
        "median_s": median,
        "per_s": placed / median if median > 0 else 0.0,
        "target_per_s": TARGET_PER_S,
    }


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, write --json."""
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", type=Path, help="write every figure to this file")
    ap.add_argument("--quick", action="store_true", help="a small run for the test suite")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--runs", type=int, help="calls per strategy (median taken)")
    args = ap.parse_args(argv)
    size = QUICK if args.quick else FULL
    if args.runs:
        size = replace(size, runs=args.runs)
    rng = random.Random(args.seed)
    view = make_view(rng, size.robots)
    system = make_system(rng, size.components, size.connections)
    rows = [measure(system, view, s, size.runs) for s in STRATEGIES]
    print(
        f"Placement: {size.components} components, {size.connections} connections, "
        f"{size.robots} robots, median of {size.runs} runs (seed {args.seed})"
    )
    print(f"{'strategy':<10} {'placed':>7} {'robots':>7} {'median ms':>10} {'per s':>9} target")
    for r in rows:
        print(
            f"{r['strategy']:<10} {r['placements']:>7} {r['robots_used']:>7} "
            f"{r['median_s'] * 1000:>10.1f} {r['per_s']:>9,.0f} >= {TARGET_PER_S:,}"
            + ("" if r["feasible"] else "  (INFEASIBLE)")
        )
    print(f"(Nomad C1M: {NOMAD_C1M_PER_S:,} placements/s)")
    if args.json:
        doc = {
            "quick": args.quick,
            "seed": args.seed,
            "config": {
                "robots": size.robots,
                "components": size.components,
                "connections": size.connections,
                "runs": size.runs,
            },
            "nomad_c1m_per_s": NOMAD_C1M_PER_S,
            "results": rows,
        }
        args.json.write_text(json.dumps(doc, indent=2) + "\n")
    return 0 if all(r["feasible"] for r in rows) else 1


if __name__ == "__main__":
    sys.exit(main())
