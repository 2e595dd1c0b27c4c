"""Election benchmark on the simulator: from the allocator's death to a new allocator known by all.

Usage: python tools/bench_election.py [--json out.json] [--quick] [--seed N] [--trials N]

How it works: every figure comes from `sdrpeer.sim.ElectionSim` runs (real membership cores with
the `lan()` gossip preset, election cores with the `lan()` election preset). A cluster boots,
converges and settles on an allocator; then, several times per cluster, the allocator is killed
and the clock runs until every running robot believes in one new allocator (a higher epoch) that
claims the role. Per death:
- detected: until the first robot declares the old allocator DEAD (the membership's part);
- claimed: until the new allocator claims the role;
- known by all: until the last running robot adopts it (`ElectionSim.belief_since`).
Median and p90 (nearest rank) over every death, per cluster size. Times are virtual seconds.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from dataclasses import dataclass
from typing import Any

from sdrpeer.election import Elected
from sdrpeer.election import lan as election_lan
from sdrpeer.gossip.config import lan
from sdrpeer.gossip.messages import DEAD
from sdrpeer.sim import Cluster
from sdrpeer.sim.election import ElectionSim, run_until_settled


@dataclass(frozen=True)
class Plan:
    """What to measure: cluster sizes, clusters per size, deaths per cluster."""

    sizes: tuple[int, ...] = (10, 100)
    clusters: int = 4
    deaths: int = 5
    gap: float = 3.0
    """Virtual seconds of calm between a settled failover and the next death."""


FULL = Plan()
QUICK = Plan(sizes=(10,), clusters=1, deaths=2, gap=2.0)

_STARTED = time.perf_counter()


def progress(message: str) -> None:
    """One line of progress on stderr, with the wall seconds since the start."""
    print(f"[{time.perf_counter() - _STARTED:6.0f} s] {message}", file=sys.stderr, flush=True)


def failovers(n: int, seed: int, deaths: int, gap: float) -> list[dict[str, float | None]]:
    """Kill the allocator of one cluster `deaths` times; the timings of each failover."""
    cluster = Cluster(n, lan(), seed=seed, count_bytes=False)
    sim = ElectionSim(cluster, election_lan())
    cluster.start(spread=1.0)
    cluster.converge(timeout=60.0)
    if run_until_settled(sim, 30.0) is None:
        raise RuntimeError(f"N = {n}, seed {seed}: no allocator after boot: {sim.describe()}")
    out: list[dict[str, float | None]] = []
    for _ in range(deaths):
        cluster.run_for(gap)
        (part,) = sim.parts()
        old = sim.part_allocator(part)
        assert old, sim.describe()
        old_epoch = sim.belief(old)[0]
        t0 = cluster.now
        cluster.kill(old)
        took = run_until_settled(sim, 30.0, step=0.01)
        up = cluster.up_names()
        new = sim.part_allocator(up) if took is not None else None
        if not new or sim.belief(new)[0] <= old_epoch:
            out.append({"detected_s": None, "claimed_s": None, "known_by_all_s": None})
            continue
        seen = cluster.trace.first_seen_by(old, DEAD, after=t0)
        claims = [t for t, name, e in sim.log if name == new and isinstance(e, Elected) and t >= t0]
        known = max(sim.belief_since[cluster.index[name]] for name in up)
        out.append(
            {
                "detected_s": min(seen.values()) - t0 if seen else None,
                "claimed_s": claims[-1] - t0 if claims else None,
                "known_by_all_s": known - t0,
            }
        )
    return out


def quantile(values: list[float], q: float) -> float | None:
    """The q-quantile by nearest rank (None for no values)."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def summary(n: int, rows: list[dict[str, float | None]]) -> dict[str, Any]:
    """Median and p90 of each timing over every death of size n."""
    cell: dict[str, Any] = {"n": n, "deaths": len(rows)}
    for key in ("detected_s", "claimed_s", "known_by_all_s"):
        values = [v for r in rows if (v := r[key]) is not None]
        cell[f"{key[:-2]}_median_s"] = statistics.median(values) if values else None
        cell[f"{key[:-2]}_p90_s"] = quantile(values, 0.9)
    cell["failed"] = sum(1 for r in rows if r["known_by_all_s"] is None)
    cell["known_by_all_s"] = [r["known_by_all_s"] for r in rows]
    return cell


def show(value: float | None) -> str:
    """A figure for the table."""
    return "-" if value is None else f"{value:.2f} s"


def report(results: dict[str, Any]) -> str:
    """The human-readable table."""
    cfg = results["config"]
    out = [
        f"gossip preset lan(): probe_interval {cfg['probe_interval']} s, gossip_interval "
        f"{cfg['gossip_interval']} s; election preset lan(): grace {cfg['grace']} s",
        "",
        "Failover: allocator killed -> new allocator known by all running robots (virtual s)",
        f"{'N':>5} {'deaths':>6} {'failed':>6} {'detected p50':>13} {'claimed p50':>12} "
        f"{'known p50':>10} {'known p90':>10}",
    ]
    for c in results["failover"]:
        out.append(
            f"{c['n']:>5} {c['deaths']:>6} {c['failed']:>6} {show(c['detected_median_s']):>13} "
            f"{show(c['claimed_median_s']):>12} {show(c['known_by_all_median_s']):>10} "
            f"{show(c['known_by_all_p90_s']):>10}"
        )
    return "\n".join(out)


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, optionally write the figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="PATH", help="also write every figure to this file")
    parser.add_argument("--quick", action="store_true", help="one small cluster: a smoke test")
    parser.add_argument("--seed", type=int, default=1, help="base seed of every run")
    parser.add_argument("--trials", type=int, help="clusters per size (each kills several times)")
    args = parser.parse_args(argv)
    plan = QUICK if args.quick else FULL
    clusters = args.trials or plan.clusters
    began = time.perf_counter()
    cells = []
    for n in plan.sizes:
        rows: list[dict[str, float | None]] = []
        for k in range(clusters):
            rows += failovers(n, args.seed + 1000 * k + n, plan.deaths, plan.gap)
            done = [t for r in rows if (t := r["known_by_all_s"]) is not None]
            middle = statistics.median(done) if done else None
            progress(
                f"N = {n}, cluster {k + 1}/{clusters}: {len(done)} failovers, p50 {show(middle)}"
            )
        cells.append(summary(n, rows))
    gossip, election = lan(), election_lan()
    results: dict[str, Any] = {
        "quick": args.quick,
        "seed": args.seed,
        "config": {
            "preset": "lan",
            "probe_interval": gossip.probe_interval,
            "gossip_interval": gossip.gossip_interval,
            "grace": election.grace,
            "startup_grace": election.startup_grace,
        },
        "failover": cells,
        "wall_s": time.perf_counter() - began,
    }
    print(report(results))
    print(f"\n(benchmark took {results['wall_s']:.0f} wall s)")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
