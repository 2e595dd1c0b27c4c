"""Dashboard smoothness: 50 robots and 200 components, live, in a real headless Chromium.

Usage: python tools/bench_dashboard.py [--robots 50] [--components 200] [--seconds 30]
                                       [--rate 1] [--json out.json]

How it works: a synthetic fleet (`SyntheticFleet`: robots whose metrics wander, each hosting
active and standby instances, connections between components, a component failing over to its
standby every few seconds, events at 5 per second) feeds the agent's real dashboard code — the
`Feed`, its history and the SSE hub behind the real aiohttp routes — in a server thread. The page
is opened in Debian's Chromium with a 15-minute history already filled, then left to stream for
`--seconds`; `--rate` samples per second (1 is what an agent sends). The page records how long
each render of an update took (`S.perf.renders`: the JavaScript work from the messages to the
DOM, SVG and canvases) and every frame interval (`S.perf.frames`). Reported: render time per
update (median, p95, p99, max) against the 16.7 ms frame budget of 60 Hz, and frame intervals
(median, p99, share over 50 ms).
"""

from __future__ import annotations

import argparse
import asyncio
import json
import random
import statistics
import sys
import threading
import time
from pathlib import Path
from typing import Any

from aiohttp import web

from sdrpeer.api.app import build_app
from sdrpeer.dashboard.chromium import chromium_page, find_chromium, have_playwright
from sdrpeer.dashboard.feed import Feed
from sdrpeer.dashboard.routes import ROUTES
from sdrpeer.eventlog import EventLog

BUDGET_MS = 1000 / 60


class SyntheticFleet:
    """A DashboardSource (and AgentView) for `robots` robots and `components` components."""

    def __init__(self, robots: int, components: int, seed: int = 1) -> None:
        self.rng = random.Random(seed)
        self.names = [f"robot-{i + 1:02d}" for i in range(robots)]
        self.components = [f"Comp{i:03d}" for i in range(components)]
        self.active = {c: self.names[i % robots] for i, c in enumerate(self.components)}
        self.standby = {c: self.names[(i + 1) % robots] for i, c in enumerate(self.components)}
        self.suffix = dict.fromkeys(self.components, 1)
        self.metrics: dict[str, dict[str, Any]] = {
            n: {
                "cpu_pct": 20.0,
                "mem_total": 4e9,
                "mem_free": 2e9,
                "battery_pct": 90.0,
                "rssi_dbm": -48.0,
                "pos": [float(i), 0.0],
            }
            for i, n in enumerate(self.names)
        }
        self.events = EventLog()
        self.dashboard = Feed(self)
        self.events.listeners.append(self.dashboard.on_event)

    @property
    def name(self) -> str:
        return self.names[0]

    def step(self) -> None:
        """Metrics wander; now and then a component fails over to its standby."""
        for m in self.metrics.values():
            m["cpu_pct"] = min(100.0, max(0.0, m["cpu_pct"] + self.rng.uniform(-3, 3)))
            m["mem_free"] = min(4e9, max(1e8, m["mem_free"] + self.rng.uniform(-5e7, 5e7)))
            m["battery_pct"] = max(0.0, m["battery_pct"] - 0.01)
            m["rssi_dbm"] = min(-30.0, max(-70.0, m["rssi_dbm"] + self.rng.uniform(-0.5, 0.5)))
        if self.rng.random() < 0.2:
            c = self.rng.choice(self.components)
            self.active[c], self.standby[c] = self.standby[c], self.active[c]
            self.suffix[c] += 1

    def instance(self, c: str, role: str) -> str:
        return f"{c}-s{self.suffix[c]}" if role == "active" else f"{c}-s{self.suffix[c] + 1}"

    def members_view(self) -> list[dict[str, Any]]:
        hosted: dict[str, list[dict[str, Any]]] = {n: [] for n in self.names}
        for c in self.components:
            for role, where in (("active", self.active[c]), ("standby", self.standby[c])):
                hosted[where].append(
                    {
                        "name": self.instance(c, role),
                        "component": c,
                        "role": role,
                        "state": "active" if role == "active" else "inactive",
                        "cpu_pct": 1.0,
                        "rss": 20_000_000,
                        "out_bps": 1000 if role == "active" else 0,
                    }
                )
        return [
            {
                "name": n,
                "state": "alive",
                "addr": "127.0.0.1:1",
                "incarnation": 0,
                "since": 0.0,
                "api": None,
                "record_version": 1,
                "metrics": dict(self.metrics[n]),
                "links": {
                    p: {"rtt_ms": 1.0 + self.rng.random(), "jitter_ms": 0.2, "loss": 0.0}
                    for p in self.names
                    if p != n
                },
                "instances": hosted[n],
            }
            for n in self.names
        ]

    def status_view(self) -> dict[str, Any]:
        comps = [
            {
                "component": c,
                "instance": self.instance(c, "active"),
                "robot": self.active[c],
                "state": "active",
                "since": 0.0,
                "standbys": [
                    {
                        "instance": self.instance(c, "standby"),
                        "robot": self.standby[c],
                        "state": "inactive",
                        "since": 0.0,
                        "mode": "hot",
                    }
                ],
            }
            for c in self.components
        ]
        conns = [
            {
                "from": f"{a}.out",
                "to": f"{b}.inp",
                "bytes_per_s": 1000,
                "expected_bytes_per_s": None,
            }
            for a, b in zip(self.components, self.components[1:], strict=False)
        ]
        plan = {"epoch": 1, "version": 1, "allocator": self.names[0], "system": "synthetic"}
        return {
            "allocator": {"name": self.names[0], "epoch": 1},
            "plan": plan,
            "components": comps,
            "connections": conns,
        }

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        return self.events.since(since, limit)

    def agent_view(self) -> dict[str, Any]:
        return {}

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        return {}


def serve(
    fleet: SyntheticFleet, rate: float, stop: threading.Event
) -> tuple[str, threading.Thread]:
    """Serve the fleet's dashboard from a thread; ticks at `rate` per second until `stop`."""
    loop = asyncio.new_event_loop()
    where: list[str] = []
    ready = threading.Event()

    async def main() -> None:
        runner = web.AppRunner(build_app(fleet, token="bench", extra_routes=ROUTES))
        await runner.setup()
        await web.TCPSite(runner, "127.0.0.1", 0).start()
        where.append(f"http://127.0.0.1:{runner.addresses[0][1]}")
        ready.set()
        n = 0
        while not stop.is_set():
            fleet.step()
            fleet.dashboard.tick(time.time())
            for _ in range(round(5 / rate)):  # 5 events a second
                fleet.events.add(time.time(), "trap", fleet.rng.choice(fleet.names), n=n)
                n += 1
            await asyncio.sleep(1 / rate)
        fleet.dashboard.close()
        await runner.cleanup()

    thread = threading.Thread(target=lambda: loop.run_until_complete(main()), daemon=True)
    thread.start()
    if not ready.wait(10):
        raise SystemExit("the dashboard server did not start")
    return where[0], thread


def prefill(fleet: SyntheticFleet, seconds: int) -> None:
    """A full history window, as an agent that has run for `seconds` would hold."""
    start = time.time() - seconds
    for i in range(seconds):
        fleet.step()
        fleet.dashboard.history.add(start + i, fleet.members_view())
        fleet.dashboard.moments.observe(start + i, fleet.status_view())


def pct(values: list[float], q: float) -> float:
    ordered = sorted(values)
    return ordered[min(len(ordered) - 1, int(q * len(ordered)))] if ordered else float("nan")


def measure(args: argparse.Namespace) -> dict[str, Any]:
    executable = find_chromium()
    if executable is None or not have_playwright():
        raise SystemExit("needs Chromium (apt-get install chromium) and Playwright (pip)")
    fleet = SyntheticFleet(args.robots, args.components)
    prefill(fleet, args.history)
    stop = threading.Event()
    url, thread = serve(fleet, args.rate, stop)
    try:
        with chromium_page(executable, 1600, 1200) as page:
            t0 = time.monotonic()
            page.goto(url + "/")
            page.wait_for_function(
                "() => window.__sdrpeer && window.__sdrpeer.perf.samples >= 1", timeout=60_000
            )
            first_s = time.monotonic() - t0
            page.evaluate(
                "() => { window.__sdrpeer.perf.renders = []; window.__sdrpeer.perf.frames = []; }"
            )
            time.sleep(args.seconds)
            perf = page.evaluate("() => window.__sdrpeer.perf")
            errors = list(page.errors)
    finally:
        stop.set()
        thread.join(10)
    renders = [float(r[1]) for r in perf["renders"]]
    parts: dict[str, list[float]] = {}
    for r in perf["renders"]:
        for part, ms in r[2].items():
            parts.setdefault(part, []).append(float(ms))
    frames = [float(ms) for ms in perf["frames"]]
    return {
        "robots": args.robots,
        "components": args.components,
        "rate_per_s": args.rate,
        "seconds": args.seconds,
        "history_s": args.history,
        "first_sample_s": round(first_s, 3),
        "samples": perf["samples"],
        "renders": len(renders),
        "render_ms": {
            "median": statistics.median(renders) if renders else None,
            "p95": pct(renders, 0.95),
            "p99": pct(renders, 0.99),
            "max": max(renders, default=None),
        },
        "frame_ms": {
            "median": statistics.median(frames) if frames else None,
            "p99": pct(frames, 0.99),
            "over_50ms": sum(1 for f in frames if f > 50) / max(1, len(frames)),
        },
        "part_ms_median": {p: round(statistics.median(v), 2) for p, v in sorted(parts.items())},
        "console_errors": errors,
    }


def report(r: dict[str, Any]) -> str:
    rm, fm = r["render_ms"], r["frame_ms"]
    verdict = "within" if rm["p95"] <= BUDGET_MS else "OVER"
    return "\n".join(
        [
            f"dashboard: {r['robots']} robots, {r['components']} components, {r['rate_per_s']:g} "
            f"samples/s, {r['seconds']} s streamed after a {r['history_s']} s history",
            f"first sample drawn after page load: {r['first_sample_s']:.2f} s",
            f"{'figure':<34}{'median':>9}{'p95':>9}{'p99':>9}{'max':>9}",
            f"{'render per update (ms)':<34}{rm['median']:>9.2f}{rm['p95']:>9.2f}{rm['p99']:>9.2f}"
            f"{rm['max']:>9.2f}",
            f"{'frame interval (ms)':<34}{fm['median']:>9.2f}{'':>9}{fm['p99']:>9.2f}",
            f"frames over 50 ms: {100 * fm['over_50ms']:.1f} %   samples drawn: {r['samples']}   "
            f"console errors: {len(r['console_errors'])}",
            "median ms by part: "
            + ", ".join(f"{p} {ms:.2f}" for p, ms in r["part_ms_median"].items()),
            f"render p95 vs the 60 Hz frame budget ({BUDGET_MS:.1f} ms): {verdict}",
        ]
    )


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    p.add_argument("--robots", type=int, default=50)
    p.add_argument("--components", type=int, default=200)
    p.add_argument("--seconds", type=float, default=30.0)
    p.add_argument("--rate", type=float, default=1.0, help="samples per second")
    p.add_argument("--history", type=int, default=900, help="seconds of history already kept")
    p.add_argument("--json", type=Path)
    args = p.parse_args(argv)
    result = measure(args)
    print(report(result))
    if args.json:
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(result, indent=2))
        print(f"wrote {args.json}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
