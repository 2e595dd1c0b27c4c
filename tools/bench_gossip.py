"""Gossip benchmark on the simulator: convergence, bandwidth, failure detection, sim speed.

Usage: python tools/bench_gossip.py [--json out.json] [--quick] [--seed N]

How it works: every figure comes from `sdrpeer.sim.Cluster` runs of the real membership core with
the `lan()` preset; clusters boot through robot r0000 and converge with no loss, then the loss under
test is switched on. Times are virtual seconds read from the cores' events; wall seconds are only
used for the simulator's own speed.
- convergence: a 450-byte `set_record` on a random robot; the time until 99.99 % of the robots
  (the originator included) reported that version; median over trials, per (N, loss);
- bandwidth: bytes each robot sends per second (`len(packet_body) + OVERHEAD`) over 60 virtual
  seconds at N = 1,000 while one robot is killed and the previous one restarted every 10 s;
  robots that took part in the churn are left out of mean and max;
- failure detection: several robots killed one after another; per death, the time until every
  running robot reported it DEAD; DEAD reports about robots never killed count as false deaths;
- sim speed: wall seconds to simulate 60 virtual seconds at N = 1,000 (bytes not counted).
"""

from __future__ import annotations

import argparse
import json
import math
import random
import statistics
import sys
import time
from dataclasses import dataclass, replace
from typing import Any

from sdrpeer.gossip.config import lan
from sdrpeer.gossip.messages import DEAD
from sdrpeer.sim import Cluster

QUANTILE = 0.9999
RECORD_SIZE = 450
SERF_BANDWIDTH = 41_000  # bytes/s per robot, serf's published model at N = 1,000
TARGET_BANDWIDTH = SERF_BANDWIDTH
TARGET_DETECTION_MEAN = 2.0
TARGET_SIM_WALL = 60.0
# (N, loss) -> (our target, serf's published model), in seconds.
CONVERGENCE_TARGETS = {(10, 0.0): (1.0, 1.6), (1000, 0.0): (2.0, 2.2), (1000, 0.3): (2.5, 3.2)}


@dataclass(frozen=True)
class Plan:
    """What to measure: the full benchmark or the quick smoke test."""

    sizes: tuple[int, ...] = (10, 100, 1000)
    losses: tuple[float, ...] = (0.0, 0.1, 0.3)
    trials_small: int = 5
    trials_large: int = 3
    big_n: int = 1000
    steady: float = 60.0
    churn_every: float = 10.0
    fd_sizes: tuple[int, ...] = (10, 100)
    fd_losses: tuple[float, ...] = (0.0, 0.3)
    fd_runs: int = 3
    fd_deaths: int = 3
    fd_gap: float = 10.0


FULL = Plan()
QUICK = Plan(
    sizes=(10, 30),
    trials_small=1,
    trials_large=1,
    big_n=60,
    steady=10.0,
    churn_every=2.5,
    fd_sizes=(10,),
    fd_runs=1,
    fd_deaths=2,
    fd_gap=6.0,
)


_STARTED = time.perf_counter()


def progress(message: str) -> None:
    """One line of progress on stderr, with the wall seconds since the start."""
    print(f"[{time.perf_counter() - _STARTED:6.0f} s] {message}", file=sys.stderr, flush=True)


def booted(n: int, seed: int, *, count_bytes: bool = False) -> tuple[Cluster, float]:
    """A converged cluster of `n` robots on the lan() preset, and the wall seconds it took."""
    began = time.perf_counter()
    cluster = Cluster(n, lan(), seed=seed, count_bytes=count_bytes)
    cluster.start(spread=1.0)
    took = cluster.converge(timeout=120.0)
    wall = time.perf_counter() - began
    progress(f"N = {n} converged in {took:.2f} virtual s, {wall:.1f} wall s")
    return cluster, wall


def convergence(plan: Plan, seed: int) -> list[dict[str, Any]]:
    """Median time for a record change to reach 99.99 % (and 99 %) of robots, per (N, loss)."""
    cells: dict[tuple[int, float], list[tuple[float | None, float | None]]] = {}
    for n in plan.sizes:
        trials = plan.trials_small if n <= 100 else plan.trials_large
        for trial in range(trials):
            cluster, _ = booted(n, seed + 1000 * trial + n)
            rng = random.Random(f"{seed}/convergence/{n}/{trial}")
            for loss in plan.losses:
                cluster.set_loss(loss)
                cluster.run_for(2.0)
                full, most = spread_time(cluster, rng)
                cells.setdefault((n, loss), []).append((full, most))
                progress(
                    f"convergence N = {n}, loss {loss:.0%}, trial {trial}: {show(full)} "
                    f"(99 %: {show(most)})"
                )
                cluster.set_loss(0.0)
                cluster.run_for(1.0)
    rows = []
    for (n, loss), pairs in cells.items():
        target, serf = CONVERGENCE_TARGETS.get((n, loss), (None, None))
        rows.append(
            {
                "n": n,
                "loss": loss,
                "trials": len(pairs),
                "times_s": [full for full, _ in pairs],
                "median_s": median([full for full, _ in pairs]),
                "times_99_s": [most for _, most in pairs],
                "median_99_s": median([most for _, most in pairs]),
                "target_s": target,
                "serf_s": serf,
            }
        )
    return rows


def median(times: list[float | None]) -> float | None:
    """The median, a missing time counting as infinite (None if the median is infinite)."""
    value = statistics.median([math.inf if t is None else t for t in times])
    return value if math.isfinite(value) else None


def spread_time(
    cluster: Cluster, rng: random.Random, timeout: float = 30.0
) -> tuple[float | None, float | None]:
    """Virtual seconds until 99.99 % and 99 % of the robots have a new record of a random robot
    (None: not within `timeout`)."""
    owner = rng.choice(cluster.up_names())
    began = cluster.now
    version = cluster.set_record(owner, rng.randbytes(RECORD_SIZE))
    up = len(cluster.up_names())
    need, most = math.ceil(QUANTILE * up), math.ceil(0.99 * up)

    def arrived() -> bool:
        return len(cluster.trace.record_arrivals(owner, version, began)) >= need

    cluster.wait_for(arrived, timeout, step=0.05)
    times = sorted(cluster.trace.record_arrivals(owner, version, began).values())
    return (
        times[need - 1] - began if len(times) >= need else None,
        times[most - 1] - began if len(times) >= most else None,
    )


def speed_and_bandwidth(plan: Plan, seed: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """Sim speed (steady state, bytes not counted), then bandwidth per robot under churn."""
    n = plan.big_n
    cluster, boot_wall = booted(n, seed + 7)
    began = time.perf_counter()
    cluster.run_for(plan.steady)
    progress(f"sim speed: {plan.steady} virtual s in {time.perf_counter() - began:.1f} wall s")
    speed = {
        "n": n,
        "virtual_s": plan.steady,
        "wall_s": time.perf_counter() - began,
        "bootstrap_wall_s": boot_wall,
        "target_wall_s": TARGET_SIM_WALL,
    }
    cluster.count_bytes = True
    rng = random.Random(f"{seed}/churn")
    churned: list[str] = []

    def churn() -> None:
        if churned:
            cluster.restart(churned[-1])
        victim = rng.choice([x for x in cluster.up_names()[1:] if x not in churned])
        cluster.kill(victim)
        churned.append(victim)

    t1 = cluster.now
    for k in range(int(plan.steady / plan.churn_every)):
        cluster.schedule(t1 + (k + 0.5) * plan.churn_every, churn)
    first, first_dgrams = list(cluster.sent_bytes), list(cluster.sent_datagrams)
    cluster.run_for(plan.steady)
    window = (t1, cluster.now)
    churned_rates = [
        (cluster.sent_bytes[i] - first[i]) / uptime(cluster, i, *window)
        for i in (cluster.index[name] for name in churned)
        if uptime(cluster, i, *window) > 1.0
    ]
    steady = [i for i, name in enumerate(cluster.names) if name not in churned]
    rates = [(cluster.sent_bytes[i] - first[i]) / (cluster.now - t1) for i in steady]
    dgrams = [(cluster.sent_datagrams[i] - first_dgrams[i]) / (cluster.now - t1) for i in steady]
    bandwidth = {
        "n": n,
        "duration_s": cluster.now - t1,
        "mean_bytes_per_s": statistics.fmean(rates),
        "max_bytes_per_s": max(rates),
        "max_robot": cluster.names[steady[rates.index(max(rates))]],
        "mean_datagrams_per_s": statistics.fmean(dgrams),
        "churned": len(churned),
        "max_bytes_per_s_churned": max(churned_rates, default=0.0),
        "target_bytes_per_s": TARGET_BANDWIDTH,
    }
    return speed, bandwidth


def uptime(cluster: Cluster, i: int, t1: float, t2: float) -> float:
    """Seconds node i was running within [t1, t2]."""
    events = sorted(
        [(t, 1) for t in cluster.trace.boots[i]] + [(t, -1) for t in cluster.trace.downs[i]]
    )
    up, since, total = False, t1, 0.0
    for t, change in events:
        if t > t2:
            break
        if up and t > t1:
            total += t - max(since, t1)
        up, since = change > 0, t
    if up:
        total += t2 - max(since, t1)
    return total


def failure_detection(plan: Plan, seed: int) -> list[dict[str, Any]]:
    """Time from a robot's death until all others mark it DEAD; false deaths under loss."""
    rows = []
    for n in plan.fd_sizes:
        for loss in plan.fd_losses:
            times: list[float] = []
            undetected = false_deaths = 0
            for run in range(plan.fd_runs):
                cluster, _ = booted(n, seed + 31 * run + n)
                rng = random.Random(f"{seed}/fd/{n}/{loss}/{run}")
                cluster.set_loss(loss)
                loss_began = cluster.now
                cluster.run_for(5.0)
                for _ in range(plan.fd_deaths):
                    victim = rng.choice(cluster.up_names()[1:])
                    cluster.kill(victim)
                    killed = cluster.now
                    others = cluster.up_names()
                    cluster.run_for(plan.fd_gap)
                    agreed = cluster.trace.when_all_see(victim, DEAD, others, after=killed)
                    if agreed is None:
                        undetected += 1
                    else:
                        times.append(agreed - killed)
                false_deaths += len(cluster.trace.false_deaths(after=loss_began))
            progress(f"failure detection N = {n}, loss {loss:.0%}: {times}")
            rows.append(
                {
                    "n": n,
                    "loss": loss,
                    "deaths": len(times) + undetected,
                    "undetected": undetected,
                    "mean_s": statistics.fmean(times) if times else None,
                    "p50_s": quantile(times, 0.50),
                    "p99_s": quantile(times, 0.99),
                    "false_deaths": false_deaths,
                    "target_mean_s": TARGET_DETECTION_MEAN,
                }
            )
    return rows


def quantile(values: list[float], q: float) -> float | None:
    """The q-quantile by nearest rank (None for no values)."""
    if not values:
        return None
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, max(0, math.ceil(q * len(ordered)) - 1))]


def show(value: float | None, unit: str = "s") -> str:
    """A figure for the table."""
    if value is None:
        return "-"
    return f"{value:.2f} {unit}" if unit == "s" else f"{value:,.0f} {unit}"


def report(results: dict[str, Any]) -> str:
    """The human-readable table of every figure measured."""
    cfg = results["config"]
    out = [
        f"preset lan(): probe_interval {cfg['probe_interval']} s, gossip_interval "
        f"{cfg['gossip_interval']} s, fanout {cfg['gossip_fanout']}, "
        f"push_pull_interval {cfg['push_pull_interval']} s",
    ]
    if "convergence" in results:
        out += [
            "",
            "Convergence (record change reaching 99.99 % of robots; median; '-': not in 30 s)",
            f"{'N':>6} {'loss':>5} {'trials':>6} {'median':>9} {'target':>8} {'serf':>8} "
            f"{'99 %':>8}",
        ]
        for r in results["convergence"]:
            out.append(
                f"{r['n']:>6} {r['loss']:>5.0%} {r['trials']:>6} {show(r['median_s']):>9} "
                f"{show(r['target_s']):>8} {show(r['serf_s']):>8} {show(r['median_99_s']):>8}"
            )
    if "bandwidth" in results:
        bw = results["bandwidth"]
        out += [
            "",
            f"Bandwidth per robot at N = {bw['n']} ({bw['duration_s']:.0f} s, churn, "
            f"{bw['churned']} churned robots left out)",
            f"  mean {show(bw['mean_bytes_per_s'], 'B/s')}, "
            f"max {show(bw['max_bytes_per_s'], 'B/s')} ({bw['max_robot']}) "
            f"({bw['mean_datagrams_per_s']:.1f} datagrams/s); "
            f"target < {show(bw['target_bytes_per_s'], 'B/s')} (serf)",
            f"  churned robots, per second up: max {show(bw['max_bytes_per_s_churned'], 'B/s')}",
        ]
    if "failure_detection" in results:
        out += [
            "",
            "Failure detection (death -> all others mark DEAD)",
            f"{'N':>6} {'loss':>5} {'deaths':>6} {'mean':>8} {'p50':>8} {'p99':>8} "
            f"{'missed':>6} {'false':>6}",
        ]
        for r in results["failure_detection"]:
            out.append(
                f"{r['n']:>6} {r['loss']:>5.0%} {r['deaths']:>6} {show(r['mean_s']):>8} "
                f"{show(r['p50_s']):>8} {show(r['p99_s']):>8} {r['undetected']:>6} "
                f"{r['false_deaths']:>6}"
            )
        out.append(f"  targets: mean <= {TARGET_DETECTION_MEAN:.1f} s, 0 false deaths")
    if "sim_speed" in results:
        sp = results["sim_speed"]
        out += [
            "",
            f"Sim speed: {sp['virtual_s']:.0f} virtual s at N = {sp['n']} in "
            f"{sp['wall_s']:.1f} wall s (target < {sp['target_wall_s']:.0f} s); "
            f"bootstrap {sp['bootstrap_wall_s']:.1f} wall s",
        ]
    return "\n".join(out)


SECTIONS = ("convergence", "bandwidth", "detection")
"""What `--only` can pick; `bandwidth` also measures the sim speed (they share one cluster)."""


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, optionally write the figures as JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--json", metavar="PATH", help="also write every figure to this file")
    parser.add_argument("--quick", action="store_true", help="tiny sizes: a smoke test")
    parser.add_argument("--seed", type=int, default=1, help="base seed of every run")
    parser.add_argument("--only", help=f"comma-separated subset of {', '.join(SECTIONS)}")
    parser.add_argument("--sizes", help="convergence cluster sizes, comma-separated")
    parser.add_argument("--trials", type=int, help="trials per convergence cell and detection runs")
    args = parser.parse_args(argv)
    plan = QUICK if args.quick else FULL
    if args.sizes:
        plan = replace(plan, sizes=tuple(int(x) for x in args.sizes.split(",")))
    if args.trials:
        plan = replace(plan, trials_small=args.trials, trials_large=args.trials)
        plan = replace(plan, fd_runs=args.trials)
    only = set(args.only.split(",")) if args.only else set(SECTIONS)
    if only - set(SECTIONS):
        parser.error(f"--only: unknown section(s) {', '.join(sorted(only - set(SECTIONS)))}")
    cfg = lan()
    began = time.perf_counter()
    results: dict[str, Any] = {
        "quick": args.quick,
        "seed": args.seed,
        "config": {
            "preset": "lan",
            "probe_interval": cfg.probe_interval,
            "gossip_interval": cfg.gossip_interval,
            "gossip_fanout": cfg.gossip_fanout,
            "push_pull_interval": cfg.push_pull_interval,
        },
    }
    if "bandwidth" in only:
        results["sim_speed"], results["bandwidth"] = speed_and_bandwidth(plan, args.seed)
    if "convergence" in only:
        results["convergence"] = convergence(plan, args.seed)
    if "detection" in only:
        results["failure_detection"] = failure_detection(plan, args.seed)
    results["wall_s"] = time.perf_counter() - began
    print(report(results))
    print(f"\n(benchmark took {results['wall_s']:.0f} wall s)")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as f:
            json.dump(results, f, indent=2)
    return 0


if __name__ == "__main__":
    sys.exit(main())
