"""Agent footprint benchmark: RSS, idle CPU and gossip bandwidth of real agents in a local lab.

Usage: python tools/bench_agent.py [--json out.json] [--seconds 30] [--settle 5] [--robots 3]

How it works: starts a lab of real `sdrpeer agent` processes on loopback (`sdrpeer.lab.up`, the
`lan` preset, the lab's default robot files from examples/robots), waits until every agent sees
every robot alive, lets it settle, then measures each agent over the window:
- RSS: psutil `memory_info().rss` sampled once a second; max and median (USS once at the end);
- idle CPU: psutil `cpu_times()` (user + system) delta over the window / wall time, as % of one
  core (the agents are idle: nobody calls their API during the window);
- gossip bandwidth: the `messages.bytes_in/bytes_out` counters of `GET /v1/agent` at the start
  and end of the window, divided by its wall time (datagram bytes, header included);
- records: each agent's own `record_version` at both ends (versions published per second), the
  encoded size of each live record (rebuilt from `/v1/members` and passed through
  `sdrpeer.record.robot.encode_record`), and the encoded size of a synthetic record with 10
  peers and 10 instances.
The lab is always stopped (SIGTERM, then SIGKILL), also on error or Ctrl-C.
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

import psutil

from sdrpeer.client import AgentClient
from sdrpeer.errors import SdrpeerError
from sdrpeer.lab.files import default_robot_files
from sdrpeer.lab.up import RunningLab, UpOptions, log_tail, start_lab
from sdrpeer.record.robot import (
    LinkStats,
    LinkSummary,
    Metrics,
    RobotRecord,
    encode_record,
    reference_record,
)

MIB = 1024 * 1024
TARGET_RSS_MB = 40.0  # MiB
TARGET_CPU_PCT = 2.0  # % of one core
SAMPLE_EVERY = 1.0


# --- record size ------------------------------------------------------------------------------


def record_from_member(member: dict[str, Any]) -> RobotRecord | None:
    """The record a `/v1/members` entry shows, rebuilt so it can be encoded again."""
    m = member.get("metrics")
    if not m:
        return None
    pos = m.get("pos")
    metrics = Metrics(
        float(m["cpu_pct"]),
        int(m["mem_total"]),
        int(m["mem_free"]),
        m.get("battery_pct"),
        m.get("rssi_dbm"),
        None if pos is None else (float(pos[0]), float(pos[1])),
    )
    summary = member.get("link_summary") or {}
    t = summary.get("typical")
    links = LinkSummary(
        peers=int(summary.get("peers") or 0),
        typical=None if not t else LinkStats(t["rtt_ms"], t["jitter_ms"], t["loss"]),
        bad=int(summary.get("bad") or 0),
        listed={
            peer: LinkStats(float(s["rtt_ms"]), float(s["jitter_ms"]), float(s["loss"]))
            for peer, s in (summary.get("listed") or {}).items()
        },
    )
    return RobotRecord(metrics, links, member.get("api"), 0, ())


# --- measuring -----------------------------------------------------------------------------------


def gossip_counters(api: str) -> dict[str, Any]:
    """bytes_in/bytes_out/in/out of one agent, from GET /v1/agent."""
    return dict(AgentClient(api, timeout=3.0).agent()["messages"])


def own_member(api: str, name: str) -> dict[str, Any]:
    """The agent's own entry of GET /v1/members."""
    members = AgentClient(api, timeout=3.0).members()
    return next(m for m in members if m["name"] == name)


def measure(running: RunningLab, seconds: float) -> list[dict[str, Any]]:
    """Sample every agent for `seconds`; one result dict per robot."""
    robots = running.lab.robots
    procs = {r.name: psutil.Process(int(r.pid or 0)) for r in robots}
    start_counters = {r.name: gossip_counters(str(r.api)) for r in robots}
    start_versions = {r.name: own_member(str(r.api), r.name)["record_version"] for r in robots}
    start_cpu = {n: p.cpu_times() for n, p in procs.items()}
    t0 = time.monotonic()
    rss: dict[str, list[int]] = {n: [] for n in procs}
    next_sample = t0
    while True:
        for name, proc in procs.items():
            rss[name].append(proc.memory_info().rss)
        problems = running.problems()
        if problems:
            raise SdrpeerError("; ".join(problems))
        next_sample += SAMPLE_EVERY
        if next_sample - t0 > seconds:
            break
        time.sleep(max(0.0, next_sample - time.monotonic()))
    time.sleep(max(0.0, t0 + seconds - time.monotonic()))
    end_cpu = {n: p.cpu_times() for n, p in procs.items()}
    wall = time.monotonic() - t0
    results = []
    for robot in robots:
        name, api = robot.name, str(robot.api)
        end = gossip_counters(api)
        member = own_member(api, name)
        a, b = start_cpu[name], end_cpu[name]
        cpu_s = (b.user - a.user) + (b.system - a.system)
        record = record_from_member(member)
        uss = procs[name].memory_full_info().uss
        results.append(
            {
                "robot": name,
                "pid": robot.pid,
                "window_s": round(wall, 2),
                "rss_samples": len(rss[name]),
                "rss_max_mib": round(max(rss[name]) / MIB, 2),
                "rss_median_mib": round(statistics.median(rss[name]) / MIB, 2),
                "uss_end_mib": round(uss / MIB, 2),
                "cpu_pct_of_core": round(100.0 * cpu_s / wall, 3),
                "cpu_seconds": round(cpu_s, 3),
                "gossip_in_bytes_per_s": round(
                    (end["bytes_in"] - start_counters[name]["bytes_in"]) / wall, 1
                ),
                "gossip_out_bytes_per_s": round(
                    (end["bytes_out"] - start_counters[name]["bytes_out"]) / wall, 1
                ),
                "datagrams_in_per_s": round((end["in"] - start_counters[name]["in"]) / wall, 2),
                "datagrams_out_per_s": round((end["out"] - start_counters[name]["out"]) / wall, 2),
                "record_version_start": start_versions[name],
                "record_version_end": member["record_version"],
                "records_published_per_s": round(
                    (member["record_version"] - start_versions[name]) / wall, 2
                ),
                "live_record_bytes": None if record is None else len(encode_record(record)),
            }
        )
    return results


# --- report --------------------------------------------------------------------------------------


def table(results: list[dict[str, Any]]) -> str:
    """The per-agent figures next to the targets."""
    head = (
        f"{'robot':<9} {'RSS max':>8} {'RSS med':>8} {'USS':>7} {'CPU %':>7} "
        f"{'in B/s':>8} {'out B/s':>8} {'rec/s':>6} {'rec B':>6}"
    )
    lines = [head, "-" * len(head)]
    for r in results:
        lines.append(
            f"{r['robot']:<9} {r['rss_max_mib']:>8.1f} {r['rss_median_mib']:>8.1f} "
            f"{r['uss_end_mib']:>7.1f} {r['cpu_pct_of_core']:>7.2f} "
            f"{r['gossip_in_bytes_per_s']:>8.0f} {r['gossip_out_bytes_per_s']:>8.0f} "
            f"{r['records_published_per_s']:>6.2f} {r['live_record_bytes'] or 0:>6}"
        )
    rss = max(r["rss_max_mib"] for r in results)
    cpu = max(r["cpu_pct_of_core"] for r in results)
    lines += [
        "",
        "(RSS/USS in MiB; CPU in % of one core; in/out = gossip datagram bytes per second;",
        " rec/s = own record versions published per second; rec B = live record size)",
        "",
        f"{'target':<28} {'measured (worst agent)':>24}  verdict",
        f"{'RSS <= 40 MiB':<28} {rss:>20.1f} MiB  {_verdict(rss <= TARGET_RSS_MB)}",
        f"{'idle CPU <= 2 % of a core':<28} {cpu:>22.2f} %  {_verdict(cpu <= TARGET_CPU_PCT)}",
    ]
    return "\n".join(lines)


def _verdict(ok: bool) -> str:
    return "ok" if ok else "MISSED"


def run(args: argparse.Namespace, lab_dir: Path) -> dict[str, Any]:
    """Start the lab, settle, measure, stop the lab; the JSON report."""
    robot_files = default_robot_files()
    options = UpOptions(
        robots=args.robots,
        lab_dir=lab_dir,
        preset="lan",
        robot_files=robot_files.resolve() if robot_files else None,
        timeout=30.0,
    )
    running = start_lab(options, say=lambda line: print(line, flush=True))
    try:
        print(f"lab up; settling {args.settle:g} s, then measuring {args.seconds:g} s", flush=True)
        time.sleep(args.settle)
        if running.problems():
            raise SdrpeerError("; ".join(running.problems()))
        results = measure(running, args.seconds)
    except BaseException:
        for robot in running.lab.robots:
            tail = log_tail(robot.log)
            if tail:
                print(f"{robot.name} log tail:\n{tail}", file=sys.stderr)
        raise
    finally:
        for line in running.stop():
            print(f"  {line}", flush=True)
    synthetic = encode_record(reference_record())
    return {
        "preset": "lan",
        "robots": args.robots,
        "robot_files": str(robot_files) if robot_files else "generated",
        "settle_s": args.settle,
        "window_s": args.seconds,
        "python": sys.version.split()[0],
        "cpu_count": psutil.cpu_count(),
        "targets": {"rss_max_mib": TARGET_RSS_MB, "idle_cpu_pct_of_core": TARGET_CPU_PCT},
        "agents": results,
        "record_bytes_10_peers_10_instances": len(synthetic),
        "verdict": {
            "rss": all(r["rss_max_mib"] <= TARGET_RSS_MB for r in results),
            "cpu": all(r["cpu_pct_of_core"] <= TARGET_CPU_PCT for r in results),
        },
    }


def main(argv: list[str] | None = None) -> int:
    """Entry point."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--json", type=Path, metavar="FILE", help="write the figures as JSON")
    parser.add_argument("--seconds", type=float, default=30.0, help="measurement window (30)")
    parser.add_argument("--settle", type=float, default=5.0, help="wait after convergence (5)")
    parser.add_argument("--robots", type=int, default=3, help="agents in the lab (3)")
    args = parser.parse_args(argv)
    if args.seconds < 2 or args.settle < 0 or args.robots < 1:
        parser.error("need --seconds >= 2, --settle >= 0, --robots >= 1")
    with tempfile.TemporaryDirectory(prefix="sdrpeer-bench-agent-") as tmp:
        try:
            report = run(args, Path(tmp))
        except SdrpeerError as exc:
            print(f"error: {exc}", file=sys.stderr)
            return 1
        except KeyboardInterrupt:
            return 130
    print()
    print(table(report["agents"]))
    print(
        f"\nrecord with 10 peers + 10 instances: {report['record_bytes_10_peers_10_instances']} "
        "bytes encoded (sdrpeer.record.robot.encode_record)"
    )
    if args.json:
        args.json.write_text(json.dumps(report, indent=2) + "\n")
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
