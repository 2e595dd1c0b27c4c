"""Component host footprint: spawn to INACTIVE and idle RSS, through the agent's own supervisor.

Usage: python tools/bench_host.py [--runs 10] [--json out.json] [--target pkg.mod:Class]

Each run starts one host exactly as an agent does (`sdrpeer.runtime.supervisor.Supervisor`: a
launcher, a control socket pair, a per-instance log), records the supervisor's own spawn-to-
INACTIVE latency, waits one second idle, and measures the host's RSS with psutil. Targets (the
components issue): spawn to INACTIVE <= 150 ms, idle host <= 25 MB (10^6 bytes) RSS. Medians are
quoted.
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import sys
import tempfile
from pathlib import Path
from typing import Any

from sdrpeer.runtime.config import fast_test as supervisor_fast
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.runtime.supervisor import Supervisor

TARGET_START_S = 0.150
TARGET_RSS_MB = 25.0
"""The issue's 25 MB, in decimal megabytes (23.8 MiB)."""
DEFAULT_TARGET = "components.camera:Camera"


async def one_run(target: str, data_dir: Path, idle: float) -> tuple[float, int]:
    """(spawn to INACTIVE in seconds, RSS bytes after `idle` s) of one host."""
    spec = InstanceSpec.from_json({"name": "bench", "target": target, "desired": "inactive"})
    sup = Supervisor(spec, data_dir, supervisor_fast())
    sup.start()
    try:
        async with asyncio.timeout(15.0):
            while sup.start_latency is None:  # noqa: ASYNC110 (the supervisor sets it)
                await asyncio.sleep(0.002)
        latency = sup.start_latency
        sup.sample()
        await asyncio.sleep(idle)
        _, rss = sup.sample()
        return latency, rss
    finally:
        await sup.stop()


async def measure(target: str, runs: int, idle: float) -> dict[str, Any]:
    """Every run's figures and their medians."""
    starts: list[float] = []
    rss: list[int] = []
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(runs):
            s, r = await one_run(target, Path(tmp) / f"run{i}", idle)
            starts.append(s)
            rss.append(r)
    return {
        "target": target,
        "runs": runs,
        "start_to_inactive_s": starts,
        "rss_bytes": rss,
        "start_median_s": statistics.median(starts),
        "rss_median_mib": statistics.median(rss) / 2**20,
        "rss_median_mb": statistics.median(rss) / 1e6,
        "target_start_s": TARGET_START_S,
        "target_rss_mb": TARGET_RSS_MB,
    }


def report(r: dict[str, Any]) -> str:
    """The result table."""
    ok_s = "ok" if r["start_median_s"] <= TARGET_START_S else "MISSED"
    ok_m = "ok" if r["rss_median_mb"] <= TARGET_RSS_MB else "MISSED"
    starts = sorted(r["start_to_inactive_s"])
    return "\n".join(
        [
            f"host {r['target']}, {r['runs']} runs (through the agent's Supervisor)",
            f"{'figure':<28}{'median':>10}{'min':>10}{'max':>10}{'target':>10}  verdict",
            f"{'spawn to INACTIVE (ms)':<28}{r['start_median_s'] * 1000:>10.0f}"
            f"{starts[0] * 1000:>10.0f}{starts[-1] * 1000:>10.0f}"
            f"{TARGET_START_S * 1000:>10.0f}  {ok_s}",
            f"{'idle RSS (MB = 10^6 bytes)':<28}{r['rss_median_mb']:>10.1f}"
            f"{min(r['rss_bytes']) / 1e6:>10.1f}{max(r['rss_bytes']) / 1e6:>10.1f}"
            f"{TARGET_RSS_MB:>10.1f}  {ok_m}",
            f"{'idle RSS (MiB)':<28}{r['rss_median_mib']:>10.1f}"
            f"{min(r['rss_bytes']) / 2**20:>10.1f}{max(r['rss_bytes']) / 2**20:>10.1f}",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    """Run the benchmark, print the table, write --json."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--idle", type=float, default=1.0)
    parser.add_argument("--target", default=DEFAULT_TARGET)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    result = asyncio.run(measure(args.target, args.runs, args.idle))
    print(report(result))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
